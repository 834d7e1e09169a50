"""``roboisf demo``: the built-in demonstration — the paper's two studies end to end.

For the cone (Ø87 mm, 71°, 102.97 mm deep) and the VWACF (Ø88.15 mm, 39 mm arc, 0° → 90°), on an
ABB IRB 7600-500/2.55 with a Ø10 mm ball, each with the ``paper`` scenario's truth (a robot
softer than the nominal model, bending links, springback partly compensating the robot's
deflection; ``docs/virtual-cell.md``), so the analysis reproduces the paper's Table 5 shares and
prints them beside the paper's: the virtual cell writes a complete study folder (force
logs in the sensors' frames, joint log, laser scans, ground truth), ``analyze`` decomposes it and
writes the report, and the toolpath is exported as programs (RAPID for the cells' ABB robot,
G-code for their CNC; ``--all-dialects`` adds KRL, FANUC LS and the program CSV) with the cell's
own frames: the work object where the cell puts the blank, the cell's tool
(sensor + holder + tool, flange to ball tip) and the configuration data of the cell's IK branch.
An index page links both reports. The folder is built in a staging folder and moved into place
when complete. The two studies are independent: by default (``--jobs 2``) the VWACF is built in
a second process while this one builds the cone.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from roboisf.cli.console import state
from roboisf.cli.outputs import DIR_HELP, Overwrite, output_dir
from roboisf.errors import InputError
from roboisf.io.atomic import staged_directory
from roboisf.progress import Progress, task

if TYPE_CHECKING:
    from roboisf.toolpath import Toolpath
    from roboisf.virtual.cell import VirtualCell

__all__ = ["DEMO_FORMATS", "build_demo", "register", "write_demo_programs"]

#: The programs the demo writes by default: one per machine of its cells — RAPID for the ABB
#: IRB 7600, G-code for the CNC. ``all_dialects`` (``--all-dialects``) adds KRL, FANUC LS and
#: the program CSV (the study's ``toolpath.csv`` is already the path as CSV).
DEMO_FORMATS = ("rapid", "gcode")
_PARTS = ("cone", "vwacf")


def build_demo(
    folder: Path,
    progress: Progress | None = None,
    *,
    scan_points: int = 1_000_000,
    force_rate: float = 1000.0,
    all_dialects: bool = False,
    jobs: int = 2,
) -> list[Path]:
    """Write the demo into ``folder`` (which exists and is empty); return the report paths.

    ``jobs`` = 2 builds the VWACF in a second process while this one builds the cone (the two
    studies are independent; the same files and numbers as one after the other, about twice the
    peak memory); 1 builds them in turn. ``all_dialects``: every program format
    (:func:`roboisf.programs.registry.program_formats`), else :data:`DEMO_FORMATS`.
    """
    from roboisf.programs.registry import program_formats
    from roboisf.report import write_index

    if jobs < 1:
        raise InputError(f"must be ≥ 1, got {jobs}", field="jobs")
    formats = tuple(f.name for f in program_formats()) if all_dialects else DEMO_FORMATS
    args: dict[str, Any] = {
        "scan_points": scan_points,
        "force_rate": force_rate,
        "formats": formats,
    }
    outcomes: dict[str, tuple[Path, list[str], list[str]]] = {}
    if jobs > 1:
        pool = _second_process_pool()
        try:
            later = {part: pool.submit(_build_part, part, folder, **args) for part in _PARTS[1:]}
            outcomes[_PARTS[0]] = _build_part(_PARTS[0], folder, progress=progress, **args)
            _say(*outcomes[_PARTS[0]][1:])
            for part, future in later.items():
                with task(progress, f"{part}: built in a second process"):
                    outcomes[part] = future.result()
                _say(*outcomes[part][1:])
        except BaseException:
            # an error or Ctrl-C here: stop the other study now rather than wait for it (the
            # staging folder it writes into is removed by the caller)
            for proc in list((getattr(pool, "_processes", None) or {}).values()):
                proc.terminate()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
    else:
        for part in _PARTS:
            outcomes[part] = _build_part(part, folder, progress=progress, **args)
            _say(*outcomes[part][1:])
    if not all_dialects:
        state.info(
            "programs: RAPID (the cells' ABB robot) and G-code (their CNC); --all-dialects "
            "adds KRL, FANUC LS and the program CSV"
        )
    state.info(
        "by construction: the cells' truth (scenario 'paper': joints 0.22x the preset's "
        "stiffness, bending links, springback partly compensating the robot) was set so these "
        "shares land on the paper's; they reproduce it, they do not confirm it "
        "(docs/virtual-cell.md)"
    )
    reports = [outcomes[part][0] for part in _PARTS]
    write_index(reports, folder / "index.html")
    return reports


def _second_process_pool() -> Any:
    """The second study's process: a one-worker ``ProcessPoolExecutor``, forked or spawned
    (:func:`_second_process_context`), that ends with this process (:func:`_follow_parent`)."""
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(
        max_workers=1,
        mp_context=_second_process_context(),
        initializer=_follow_parent,
        initargs=(os.getpid(),),
    )


def _follow_parent(parent: int, poll: float = 0.2) -> None:
    """The second study's process initializer: end this process once ``parent`` has ended
    without stopping it (SIGKILL, a closed terminal's SIGHUP, the out-of-memory killer: no
    cleanup ran there), checked every ``poll`` s by a daemon thread. A forked pool worker holds
    its own copy of the job queue's pipe, so it never read the end of it: after a killed
    ``roboisf demo`` it waited for a next job for good, holding 0.37 GB (found by trying it).
    The half-written staging folder it leaves is removed by the next run into that folder, as
    the killed parent's own."""
    import threading
    import time

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll)
        os._exit(1)  # nothing to hand back, nobody to hand it to

    threading.Thread(target=watch, name="roboisf-follow-parent", daemon=True).start()


def _second_process_context() -> Any:
    """The second study's process: forked where that is safe — on Linux, while this process
    runs no other Python thread (before the progress display's refresh thread starts: a fork
    copies no thread, only the locks they may hold; OpenBLAS's own pool is stopped and restarted
    across a fork by its fork handlers, as for the report's PNG workers) — after importing what
    both studies run, so the child starts with it loaded (spawning re-imported numpy, pandas,
    scipy, numba and roboisf: ~2 CPU-s, which on two cores the cone's process paid for too).
    Else spawned."""
    import multiprocessing
    import sys
    import threading

    fork = (
        sys.platform.startswith("linux")
        and "fork" in multiprocessing.get_all_start_methods()
        and threading.active_count() == 1
    )
    if not fork:
        return multiprocessing.get_context("spawn")
    import roboisf.decompose.pipeline
    import roboisf.report.document
    import roboisf.virtual.cell  # noqa: F401

    if threading.active_count() != 1:  # an import started a thread: not safe to fork after all
        return multiprocessing.get_context("spawn")
    state.imports_done()  # the console script's: both processes' collections skip the modules
    return multiprocessing.get_context("fork")


def _say(infos: list[str], warnings: list[str]) -> None:
    for line in warnings:
        state.warn(line)
    for line in infos:
        state.info(line)


def _build_part(
    part: str,
    folder: Path,
    *,
    scan_points: int,
    force_rate: float,
    formats: tuple[str, ...],
    progress: Progress | None = None,
) -> tuple[Path, list[str], list[str]]:
    """One paper study into ``folder / <cell name>``: virtual cell → analyze → report →
    programs. Returns (report path, the lines to print, warnings); prints nothing itself, so it
    runs as well in a worker process. BLAS on one thread throughout
    (:func:`~roboisf.robot.vjm_kernel.single_blas_thread`): the two studies' processes and
    their own threads already fill the cores."""
    from roboisf.robot.vjm_kernel import single_blas_thread

    with single_blas_thread():
        return _build_one(
            part, folder, scan_points=scan_points, force_rate=force_rate, formats=formats,
            progress=progress,
        )  # fmt: skip


def _build_one(
    part: str,
    folder: Path,
    *,
    scan_points: int,
    force_rate: float,
    formats: tuple[str, ...],
    progress: Progress | None,
) -> tuple[Path, list[str], list[str]]:
    from roboisf.cam.toolpath_csv import read_toolpath_csv
    from roboisf.decompose.pipeline import analyze, write_results
    from roboisf.virtual.cell import PAPER_TABLE5, build_study, paper_scenario_cell

    cell = paper_scenario_cell(part, scan_points=scan_points, force_rate=force_rate)
    sub = folder / cell.name
    sub.mkdir()
    with task(progress, f"{cell.name}: virtual cell"):
        study = build_study(cell, sub / "study", progress=progress)
    with task(progress, f"{cell.name}: analyze"):
        result = analyze(study, progress=progress)
        write_results(result, sub / "results", progress=progress)
    tp = read_toolpath_csv(study / "toolpath.csv")
    warnings = []
    if tp.meta.get("truncated"):  # as roboisf.cli.toolpath.warn_truncated says it
        z = float(tp.meta["reachable_tip_z"])  # type: ignore[arg-type]
        warnings.append(
            f"{cell.name}: a Ø{cell.cell.tool.ball_diameter * 1e3:g} mm ball does not fit in the "
            f"part below tip z = {z * 1e3:.3f} mm (it would touch the wall across the axis); "
            "the toolpath stops there"
        )
    write_demo_programs(cell, tp, sub / "programs", formats, progress)
    row = result.contributions.set_index("factor")
    paper = PAPER_TABLE5[part]
    infos = [
        f"{cell.name}: {len(tp)} points, R_m {row.loc['total', 'R_m']:.3f} mm; robot "
        f"compliance {row.loc['robot_compliance', 'share_percent']:.1f} % (paper "
        f"{paper['robot_share_percent']:.2f} %), springback R_m "
        f"{row.loc['springback', 'R_m']:.3f} mm (paper {paper['springback_R_m_mm']:.3f} mm)"
    ]
    vc = result.summary.vjm_check
    if vc.get("ratio") is not None:
        verdict = "holds by construction" if vc.get("by_construction") else vc.get("verdict")
        infos.append(
            f"{cell.name}: model check {verdict} — measured/VJM robot deflection "
            f"{vc['ratio']:.2f} (95 % [{vc['ci_low']:.2f}, {vc['ci_high']:.2f}])"
        )
    delta = result.summary.vjm_vs_experiment_per_axis
    if all(delta.get(k) is not None for k in "xyz"):
        infos.append(
            f"{cell.name}: Δ = mean|δ_exp| − mean|δ_VJM| x/y/z "
            + "/".join(f"{delta[k]:.2f}" for k in "xyz")
            + " mm (paper "
            + "/".join(f"{paper[f'delta_{k}_mm']:g}" for k in "xyz")
            + " mm; z: a scan sees only the wall-normal part, and the paper's VJM z was ~2x "
            "ours — docs/virtual-cell.md)"
        )
    return sub / "results" / "report.html", infos, warnings


def write_demo_programs(
    cell: VirtualCell,
    tp: Toolpath,
    folder: Path,
    formats: tuple[str, ...] = DEMO_FORMATS,
    progress: Progress | None = None,
) -> list[Path]:
    """Export ``tp`` into the new folder ``folder`` as ``toolpath.<suffix>`` in each of
    ``formats`` with the cell's frames: the work object where the cell puts the blank, the
    cell's tool (flange to ball tip, 2 kg) and the configuration data of the cell's IK branch.
    Returns the written paths (a RAPID program too long for one module is a set of files next to
    its main module)."""
    from roboisf.cam.program import RobotTool
    from roboisf.programs.export import write_toolpath
    from roboisf.programs.registry import program_formats
    from roboisf.robot.armconfig import program_config

    suffix = {f.name: f.suffixes[0] for f in program_formats()}
    bad = [f for f in formats if f not in suffix]
    if bad:
        raise InputError(
            f"unknown format {bad[0]!r}; expected one of {', '.join(suffix)}",
            field="formats",
        )
    model, T_base_work = cell.cell.robot, cell.cell.T_base_work
    tool = RobotTool(length=float(model.T_flange_tip[2, 3]), mass=2.0)
    config = program_config(model, tp, T_base_work, cell.tool_rotation)
    folder.mkdir()
    paths = []
    with task(progress, f"{cell.name}: robot programs", total=len(formats)) as advance:
        for fmt in formats:
            paths.append(folder / f"toolpath{suffix[fmt]}")
            write_toolpath(
                tp,
                paths[-1],
                fmt,
                T_base_work=T_base_work,
                tool=tool,
                tool_rotation=cell.tool_rotation,
                config=config,
            )
            advance(1)
    return paths


def register(app: typer.Typer) -> None:
    """Add ``roboisf demo`` to ``app``."""

    @app.command("demo")
    def _demo(
        output: Annotated[
            Path, typer.Option("--output", "-o", help=f"Folder to write. {DIR_HELP}")
        ] = Path("roboisf-demo"),
        overwrite: Overwrite = False,
        scan_points: Annotated[int, typer.Option(help="Points per simulated scan.")] = 1_000_000,
        force_rate: Annotated[float, typer.Option(help="Force-log sample rate [Hz].")] = 1000.0,
        all_dialects: Annotated[
            bool,
            typer.Option(
                "--all-dialects",
                help="Export the toolpath in every program format (RAPID, G-code, KRL, FANUC "
                "LS, CSV); default: RAPID for the cells' ABB robot and G-code for their CNC.",
            ),
        ] = False,
        jobs: Annotated[
            int,
            typer.Option(
                min=1,
                max=2,
                help="Studies built at once: 2 builds the VWACF in a second process beside the "
                "cone (same results; about twice the peak memory), 1 one after the other.",
            ),
        ] = 2,
    ) -> None:
        """The paper's cone and VWACF, end to end: virtual cell → analyze → report → robot programs.

        Both cells run the 'paper' scenario (roboisf virtual-cell cone --scenario paper): a
        truth set so the analysis reproduces the paper's Table 5 (robot share 40.28 % / 59.98
        %), printed beside the paper's. Opens nothing and needs no input: results land in
        OUTPUT/index.html.
        """
        output_dir(output, "demo", overwrite)
        with staged_directory(output, "demo") as stage:
            build_demo(
                stage,
                state.progress(),
                scan_points=scan_points,
                force_rate=force_rate,
                all_dialects=all_dialects,
                jobs=jobs,
            )
        state.info(f"open {output / 'index.html'}")
