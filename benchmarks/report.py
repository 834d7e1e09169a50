"""Time and size of the study report at paper scale (run by hand: python benchmarks/report.py).

Paper scale: the 71° cone, 0.5 mm step-down over 103 mm = ~206 laps; 150 points per lap.
Peers, in the same run: the naive plotly way — each figure written with ``fig.write_html`` and
its own copy of plotly.js (what an ad-hoc script does) — against the report's single file with
plotly.js once; and the PNGs as they were drawn before issue #16 (the same figures under
matplotlib's constrained layout, which draws each figure twice, and PIL's default zlib level)
against the fixed layout drawn once; and the whole report with the PNGs drawn in worker processes
while the HTML is written (the default) against all in one process (``processes=0``), the files
compared byte for byte. CPU time (``time.process_time``, plus the workers' from
``getrusage(RUSAGE_CHILDREN)``) is printed beside the wall time: on a shared machine the wall time
is contended.
"""

from __future__ import annotations

import filecmp
import io
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "src"), str(ROOT / "tests")]

from report_fixtures import make_study  # noqa: E402
from roboisf.report import document as doc  # noqa: E402
from roboisf.report import static as st  # noqa: E402
from roboisf.report import write_report  # noqa: E402
from roboisf.report.render import default_processes  # noqa: E402
from roboisf.report.schema import (  # noqa: E402
    check_contributions,
    check_per_point,
    check_summary,
)


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def parallel(study: tuple, tmp: Path) -> None:
    """The report with the PNGs in worker processes against all in one process (interleaved)."""
    n_workers = default_processes()
    runs: dict[int, list[tuple[float, float, float]]] = {0: [], n_workers: []}
    for _ in range(2):
        for procs in runs:
            w0, c0, k0 = time.perf_counter(), time.process_time(), _children_cpu()
            write_report(*study, tmp / f"procs{procs}", png=True, processes=procs)
            runs[procs].append(
                (time.perf_counter() - w0, time.process_time() - c0, _children_cpu() - k0)
            )
    a, b = tmp / "procs0", tmp / f"procs{n_workers}"
    same = filecmp.cmp(a / "report.html", b / "report.html", shallow=False) and all(
        filecmp.cmp(f, b / "figures" / f.name, shallow=False) for f in (a / "figures").iterdir()
    )
    for procs, rs in runs.items():
        walls = ", ".join(f"{w:5.2f}" for w, _, _ in rs)
        cpus = ", ".join(f"{c:4.2f}+{k:4.2f}" for _, c, k in rs)
        print(
            f"{'':>7}  report with {procs} PNG worker(s): wall {walls} s, CPU (this process + "
            f"workers) {cpus} s"
        )
    print(f"{'':>7}  same bytes (HTML and every PNG): {same}; {os.cpu_count()} CPUs")


def main() -> None:
    for laps, per_lap in ((206, 150), (412, 300)):
        study = make_study(n_laps=laps, points_per_lap=per_lap)
        n = len(study[0])
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            path = write_report(*study, Path(tmp) / "html", png=False)
            t_html = time.perf_counter() - t0
            size = path.stat().st_size
            t0 = time.perf_counter()
            write_report(*study, Path(tmp) / "full", png=True)
            t_full = time.perf_counter() - t0

            pp = check_per_point(study[0])
            c = check_contributions(study[1], name="c")
            cn = check_contributions(study[2], name="cn")
            s = check_summary(study[3])
            figs = doc._figures(pp, c, cn, s["contour_z"], True)
            t0 = time.perf_counter()
            peer_size = 0
            for fid, spec in figs.items():
                out = Path(tmp) / f"peer_{fid}.html"
                spec.plotly().write_html(out, include_plotlyjs=True)
                peer_size += out.stat().st_size
            t_peer = time.perf_counter() - t0
        print(
            f"{n:>7} points: HTML only {t_html:5.2f} s ({size / 1e6:4.1f} MB) | HTML + "
            f"{len(figs)} PNG {t_full:5.2f} s | peer (write_html per figure) {t_peer:5.2f} s, "
            f"{peer_size / 1e6:5.1f} MB in {len(figs)} files — size ratio "
            f"{peer_size / size:4.1f}x, "
            f"time ratio {t_peer / t_html:4.2f}x"
        )
        with tempfile.TemporaryDirectory() as tmp:
            parallel(study, Path(tmp))
        cpu = {"fixed layout, drawn once": 0.0, "constrained layout (before #16)": 0.0}
        for _ in range(2):  # interleaved, twice
            for mode in cpu:
                for spec in figs.values():
                    fig = spec.png()
                    c0 = time.process_time()
                    if mode.startswith("fixed"):
                        buf = io.BytesIO()
                        fig.savefig(
                            buf,
                            format="png",
                            dpi=st.DPI,
                            facecolor="white",
                            pil_kwargs={"compress_level": st.PNG_COMPRESS_LEVEL},
                        )
                    else:
                        fig.set_layout_engine("constrained")
                        fig.savefig(io.BytesIO(), format="png", dpi=st.DPI, facecolor="white")
                    cpu[mode] += time.process_time() - c0
        a, b = cpu.values()
        print(
            f"{'':>7}  9 PNGs, CPU (2 rounds): fixed layout {a:5.2f} s, constrained layout "
            f"{b:5.2f} s — ratio {a / b:4.2f}x"
        )


if __name__ == "__main__":
    main()
