"""The ``roboisf`` command line.

Every command: ``--help``; ``-o/--output`` (checked and locked before computing, never loses a
file roboisf did not write: docs/conventions.md, Outputs); exit code 0 on success, 2 on bad input
(one line on stderr naming the file/field and what was expected) or a refusal of the machine (a
full disk, a name too long, no permission, an unreachable host: one line naming the path and what
to do), 1 on an internal error, 130/143/129 when interrupted by SIGINT/SIGTERM/SIGHUP. ``-q``
silences progress and info, ``-v`` adds detail. Call :func:`main` with an argv list from tests.
"""

from __future__ import annotations

import contextlib
import faulthandler
import gc
import os
import sys
from collections.abc import Sequence

import typer

from roboisf import __version__
from roboisf.cli.console import state
from roboisf.cli.lazy import LazyCommand, LazyGroup, defer_unused_imports
from roboisf.errors import ConvergenceError, InputError
from roboisf.io.outdir import (
    SIGNAL_OUTCOMES,
    Interrupted,
    deferred_signals,
    environment_error,
    output_session,
    signal_handlers,
)
from roboisf.progress import set_notice

# every command, in the order --help lists them (the workflow first, then the building blocks),
# with the module whose register(app) adds it and its one-line help: --help lists them without
# importing their modules, running one imports only its own (tests/test_cli_startup.py checks
# this table against the commands the modules really register)
COMMANDS: tuple[LazyCommand, ...] = (
    LazyCommand(
        "demo",
        "demo",
        "The paper's cone and VWACF, end to end: virtual cell → analyze → report → robot programs.",
    ),
    LazyCommand(
        "analyze",
        "analyze",
        "Split a robot-formed part's error: springback, tool, tool holder, robot compliance.",
    ),
    LazyCommand(
        "virtual-cell",
        "analyze",
        "Write a synthetic study (CNC and robot runs with known ground truth in truth/).",
    ),
    LazyCommand("study", "study", "Study folders: draft a study.toml from the files you have."),
    LazyCommand(
        "compensate",
        "compensate",
        "Compensate the toolpath: robot/tool/holder pre-deflection and springback adjustment.",
    ),
    LazyCommand(
        "plan",
        "plan",
        "Rank work-object placements (x, y, z, yaw) and tool rotations by predicted deflection.",
    ),
    LazyCommand(
        "predict",
        "predict",
        "Predict the error of a part before it is formed: springback learned from the history, "
        "tool and holder by their compliance, robot by the VJM (identified stiffness).",
    ),
    LazyCommand(
        "history",
        "history",
        "The cell's history: analysed parts in a database (add, list, show, trend).",
    ),
    LazyCommand("part", "part", "Write a part file (TOML, mm and degrees)."),
    LazyCommand(
        "toolpath",
        "toolpath",
        "Generate a forming toolpath (step-down or spiral); write CSV, G-code, RAPID or KRL.",
    ),
    LazyCommand(
        "robot", "robot", "Robot models, joint stiffness and VJM deflection along a toolpath."
    ),
    LazyCommand(
        "tool-stiffness",
        "fem",
        "6×6 compliance of a ball-end tool (or a STEP body) about its tip, by six FE loads.",
    ),
    LazyCommand(
        "holder-stiffness",
        "fem",
        "6×6 compliance of a stepped/tapered tool holder about its nose centre (or, with "
        "--with-tool, of tool + holder in series about the tool tip).",
    ),
    LazyCommand(
        "scan",
        "scan",
        "Laser scans vs the nominal part: registration and signed deviation vectors.",
    ),
    LazyCommand(
        "online",
        "online",
        "Correct the robot while it forms: force stream → tip wrench → VJM + tool + holder "
        "compliance at the current joints → pre-deflection sent every controller cycle.",
    ),
)


class _Root(LazyGroup):
    lazy = COMMANDS


app = typer.Typer(
    name="roboisf",
    help=(
        "Measure, split and remove the geometric error of robot-formed ISF parts.\n\n"
        "Typical session:  roboisf demo   ·   roboisf analyze study/ -o results/   ·   "
        "roboisf compensate ...\n\nLengths on the command line are mm, angles degrees; files "
        "declare their own units. -q/-v may come before or after the command.\n\n"
        "roboisf's compiled kernels are built at install: in C (no numba needed) all but the "
        "online loop's, which numba compiles; --version says which are there. Where "
        "numba's cache cannot serve (a kernel edited, numba upgraded, another CPU, a read-only "
        "install) it is built once in the background after the first run, which uses numpy; "
        "ROBOISF_BACKGROUND_COMPILE=0 builds it in the foreground (and shows why a failed "
        "background build failed)."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # click's plain help: typer's rich help renderer imports rich with its markdown and
    # traceback modules, 0.19 s of the 0.3 s start-up budget (docs/conventions.md)
    rich_markup_mode=None,
    context_settings={"max_content_width": 120},
    cls=_Root,
)


def _version(value: bool) -> None:
    if value:
        from roboisf.jit import native
        from roboisf.jit.shim import HAVE_NUMBA, numba_version_installed

        typer.echo(f"roboisf {__version__}")
        typer.echo(native.describe())
        numba = (
            f"numba {numba_version_installed() or '?'} (any kernel whose C form is not built, "
            "and the tests' oracle)"
            if HAVE_NUMBA
            else "numba: not installed or switched off (ROBOISF_NUMBA=0); numpy serves"
        )
        typer.echo(numba)
        raise typer.Exit(0)


@app.callback()
def _root(
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print only errors."),
    verbose: bool = typer.Option(
        False, "--verbose", "-v", help="Print more detail: each step's time as it ends."
    ),
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Show the version and exit."
    ),
) -> None:
    state.verbosity = 0 if quiet else (2 if verbose else 1)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI with ``argv`` (without the program name); return the exit code.

    SIGINT, SIGTERM and SIGHUP (not when ignored, as under ``nohup``) unwind the stack (outputs
    in progress are discarded, previous results kept) and give 130, 143 and 129 with one line on
    stderr saying what happened to the outputs (after a hang-up, to ``/dev/null``).
    """
    args = hoist_verbosity(list(sys.argv[1:] if argv is None else argv))
    set_notice(state.notice)  # a first build of the compiled kernels says so
    try:
        with signal_handlers(), output_session() as session:
            try:
                code = _run(args)
            except (Interrupted, KeyboardInterrupt, typer.Abort) as e:
                code = e.exit_code if isinstance(e, Interrupted) else 130
            if code not in SIGNAL_OUTCOMES:  # typer turns a KeyboardInterrupt into exit code 130
                return code
            with contextlib.suppress(Interrupted), deferred_signals():
                what = "; ".join(c.outcome() for c in session.claims) or "nothing written"
                state.err.print(f"{SIGNAL_OUTCOMES[code]}; {what}", markup=False, soft_wrap=True)
            return code
    finally:
        state.verbosity = 1
        set_notice(None)


#: The root's verbosity flags; no command has options of these names.
VERBOSITY_FLAGS = frozenset({"-q", "--quiet", "-v", "--verbose"})


def hoist_verbosity(args: list[str]) -> list[str]:
    """``-q``/``-v`` anywhere before a ``--`` moved in front of the command, where the root
    reads them: ``roboisf analyze study -v`` is ``roboisf -v analyze study``. After ``--``
    every word is an argument and stays."""
    end = args.index("--") if "--" in args else len(args)
    flags = [a for a in args[:end] if a in VERBOSITY_FLAGS]
    rest = [a for a in args[:end] if a not in VERBOSITY_FLAGS]
    return flags + rest + args[end:]


def _run(args: list[str]) -> int:
    try:
        rv = app(args=args, prog_name="roboisf", standalone_mode=False)
    except InputError as e:
        _error(e)
        return 2
    except ConvergenceError as e:
        _error(e)
        return 3
    except typer.Exit as e:
        return int(e.exit_code or 0)
    except (OSError, MemoryError) as e:
        # what the machine refused (a full disk, a name too long, no permission, an unreachable
        # host, no memory): one line naming the path and what to do, like a bad input; the
        # staging folders and temporary files were removed on the way up, the locks are
        # released by the output session
        _error(environment_error(e))
        return 2
    except Exception as e:
        # usage errors (unknown option, missing argument): click's ClickException interface —
        # typer ≥ 0.16 vendors its own click, so match the interface, not the class
        show, code = getattr(e, "show", None), getattr(e, "exit_code", None)
        if callable(show) and isinstance(code, int):
            show()
            return code
        raise
    # without standalone mode click returns the code of typer.Exit/ctx.exit instead of raising
    if isinstance(rv, int) and not isinstance(rv, bool):
        return rv
    return 0


def _error(e: Exception) -> None:
    # one line on stderr, "error:" in red on a terminal (not under NO_COLOR), the message as is;
    # through click's echo, which typer has loaded already: rich (0.05–0.1 s of import) is not
    # needed to refuse an input
    color = False if os.environ.get("NO_COLOR") else None
    typer.secho("error:", fg="red", err=True, nl=False, color=color)
    typer.echo(f" {e}", err=True, color=color)


#: The variables OpenBLAS reads, in its order, for its number of threads when it is loaded.
OPENBLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def one_openblas_thread() -> None:
    """The console script's OpenBLAS runs on one thread, unless the user chose a number.

    roboisf's work is parallel in its own threads (the scans beside the logs, the kernels'
    chunks, the plan's placements) and its matrices are small, so BLAS runs pinned to one thread
    inside them anyway (:func:`~roboisf.robot.vjm_kernel.single_blas_thread`). But OpenBLAS
    starts its thread pool when it is loaded, and the pool's threads spin waiting for work for
    ~0.1 s of a core each: numpy's OpenBLAS at numpy's import and scipy's own copy when scipy
    is first imported (in ``analyze``: in the middle of the scans, a library the pinning made
    before it had not seen). Set before either is loaded, the variable leaves no pool to spin
    (``perf``: ``blas_thread_server`` 2.9 % of a paper-cone ``analyze``'s CPU, 0 % with it).
    MKL (pypardiso's FE solves) is not affected."""
    if not any(os.environ.get(v) for v in OPENBLAS_THREAD_VARIABLES):
        os.environ["OPENBLAS_NUM_THREADS"] = "1"


def entry() -> None:
    """The ``roboisf`` console script: :func:`main`, then exit with its code.

    Once the outcome is decided and reported, a second Ctrl-C (or SIGTERM) must not change it:
    one arriving after :func:`main` restored the default handlers, or during the interpreter's
    shutdown (thread pools, atexit), used to end the process by SIGINT instead of exit 130. It
    is ignored from then on; one escaping :func:`main` as KeyboardInterrupt gives 130."""
    import signal

    state.own_process = True  # a command may set process-wide policies (plan: the C heap's)
    # a crash in compiled code (the C kernels, numba's, a library's) prints where Python was —
    # the thread and the call that reached it — instead of a bare "Segmentation fault"
    faulthandler.enable()
    one_openblas_thread()
    defer_unused_imports()  # numpy.f2py, which scipy's import runs for nothing (cli/lazy.py)
    try:
        code = main()
    except KeyboardInterrupt:
        code = 130
    for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)):
        if s is not None:
            signal.signal(s, signal.SIG_IGN)
    # the interpreter's shutdown runs the cyclic garbage collector over every object the
    # command imported (numba, pandas, matplotlib: ~250 k objects) only to free memory the
    # process gives back on exit anyway: 0.4-0.6 s of a 6 s `roboisf analyze` (measured,
    # docs/speed.md). Frozen objects are skipped by it; atexit handlers, module teardown and
    # reference-counted finalizers (temporary folders, open files) run as before.
    gc.freeze()
    sys.exit(code)
