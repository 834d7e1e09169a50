"""Shared virtual studies, built once per test session and reused read-only.

Several test files need the same small virtual study (the paper's cone on a coarse path,
:data:`SMALL_CONE`). Building it (forming simulation, two scans, the logs) is the cost, so it is
built once and shared: under pytest-xdist the first worker that asks builds it in the session's
shared temporary folder while holding a file lock (pytest-xdist's documented recipe,
"Making session-scoped fixtures execute only once"), the others wait and read the same folder.

Shared studies are read-only for the tests: a test that edits one copies it first
(``shutil.copytree``). Each fixture fingerprints the study's files when it hands it out and
checks at the end of the session that nothing changed, so a test that writes into a shared study
fails instead of silently changing what the other tests read.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

# The suite runs both engines explicitly and must not leave background kernel builders behind:
# "auto" compiles in the foreground here, as before. tests/test_jit.py tests the builder.
os.environ.setdefault("ROBOISF_BACKGROUND_COMPILE", "0")

# Under pytest-xdist (`-n 2` on CI's and the developers' 2-CPU machines) each worker's OpenBLAS
# would start a thread per CPU: two workers' BLAS threads then spin against each other and the
# other worker's numba threads (in one 5-module sample, 80 s → 62 s with one BLAS thread each).
# One BLAS thread per worker, in the worker (numpy is loaded by now: threadpoolctl) and in the
# processes the tests start (the environment); roboisf's own kernel threads (jit.run_chunks) are
# left as they are (the suite checks the threaded kernels against the serial ones). MKL too (the
# FE tests' PARDISO; read when MKL loads). An explicit OPENBLAS_NUM_THREADS wins.
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1 and (
    "OPENBLAS_NUM_THREADS" not in os.environ
):
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    os.environ.setdefault("MKL_NUM_THREADS", "1")
    with contextlib.suppress(ImportError):
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1, user_api="blas")

#: The small paper cone: 2 mm step-down, 4 mm spacing (≈ 3 k toolpath points), 150 k scan
#: points, forces at 50 Hz, joints at 20 Hz (the same cell as docs/study.md's worked example).
SMALL_CONE: dict[str, float] = {
    "scan_points": 150_000,
    "force_rate": 50.0,
    "joint_rate": 20.0,
    "step_down": 2e-3,
    "spacing": 4e-3,
}


#: The fast paper cone: 2 mm step-down, 3 mm spacing, 60 k scan points, forces at 100 Hz,
#: joints at 50 Hz.
FAST_CONE: dict[str, float] = {
    "step_down": 2e-3,
    "spacing": 3e-3,
    "scan_points": 60_000,
    "force_rate": 100.0,
    "joint_rate": 50.0,
}


@contextlib.contextmanager
def _file_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (POSIX ``flock``; no lock where there is none, then
    each xdist worker builds its own copy — slower, never wrong)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    with open(path, "a+b") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _fingerprint(folder: Path) -> dict[str, tuple[int, int]]:
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _shared_study(
    tmp_path_factory: pytest.TempPathFactory, name: str, build: Callable[[Path], Any]
) -> Iterator[Path]:
    """``build(folder)`` once per session (across xdist workers) into a shared folder ``name``;
    yields the folder and checks at teardown that no test changed it."""
    root = tmp_path_factory.getbasetemp()
    if "PYTEST_XDIST_WORKER" in os.environ:
        root = root.parent  # the session's folder, shared by the workers
    root = root / "shared-studies"
    root.mkdir(parents=True, exist_ok=True)
    folder = root / name
    done = root / f"{name}.done"
    with _file_lock(root / f"{name}.lock"):
        if not done.is_file():
            build(folder)
            done.write_text(json.dumps(_fingerprint(folder)))
    before = json.loads(done.read_text())
    yield folder
    after = {k: list(v) for k, v in _fingerprint(folder).items()}
    assert after == before, f"a test changed the shared study {folder} (copy it before editing)"


@pytest.fixture(scope="session")
def small_cone_settings() -> dict[str, float]:
    """:data:`SMALL_CONE` (a copy): ``paper_cone_cell(**small_cone_settings)`` is the cell of
    :func:`small_cone_study`, for tests that build a variant of it (other equipment, a truth)."""
    return dict(SMALL_CONE)


@pytest.fixture(scope="session")
def small_cone_study(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The :data:`SMALL_CONE` virtual study, Parquet logs (``build_study``'s default). Read-only."""
    from roboisf.virtual.cell import build_study, paper_cone_cell

    yield from _shared_study(
        tmp_path_factory,
        "small-cone",
        lambda folder: build_study(paper_cone_cell(**SMALL_CONE), folder),
    )


@pytest.fixture(scope="session")
def small_cone_study_csv(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The :data:`SMALL_CONE` virtual study with roboisf CSV logs. Read-only."""
    from roboisf.virtual.cell import build_study, paper_cone_cell

    yield from _shared_study(
        tmp_path_factory,
        "small-cone-csv",
        lambda folder: build_study(paper_cone_cell(**SMALL_CONE), folder, log_format="csv"),
    )


@pytest.fixture(scope="session")
def fast_cone_settings() -> dict[str, float]:
    """:data:`FAST_CONE` (a copy): ``paper_cone_cell(**fast_cone_settings)`` is the cell of
    :func:`fast_cone_study`."""
    return dict(FAST_CONE)


@pytest.fixture(scope="session")
def fast_cone_study(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The :data:`FAST_CONE` virtual study, Parquet logs. Read-only."""
    from roboisf.virtual.cell import build_study, paper_cone_cell

    yield from _shared_study(
        tmp_path_factory,
        "fast-cone",
        lambda folder: build_study(paper_cone_cell(**FAST_CONE), folder),
    )


@pytest.fixture(scope="session")
def small_cone_analysis(small_cone_study: Path) -> Any:
    """``analyze(small_cone_study)`` (an :class:`~roboisf.decompose.pipeline.AnalysisResult`),
    once per xdist worker. Treat as read-only."""
    from roboisf.decompose.pipeline import analyze

    return analyze(small_cone_study)


@pytest.fixture(scope="session")
def online_cone() -> Callable[..., Any]:
    """``online_cone(depth, **kw)``: the virtual cell the online loop's tests form — a cone
    ``depth`` [m] deep, named ``cone-<depth in mm>``, at the paper cell's placement, 1 mm
    step-down, 2 mm spacing; ``kw`` go to :func:`roboisf.virtual.cell.virtual_cell`
    (``scan_points``, ``force_rate``, ``joint_rate``). Each call builds a new cell."""
    from roboisf.parts import Cone
    from roboisf.virtual.cell import PAPER_CELL_PLACEMENT, virtual_cell

    def make(depth: float, **kw: Any) -> Any:
        return virtual_cell(
            f"cone-{round(depth * 1e3)}",
            Cone(depth=depth),
            T_base_work=PAPER_CELL_PLACEMENT,
            step_down=1e-3,
            spacing=2e-3,
            **kw,
        )

    return make


# -- distribution over pytest-xdist workers ----------------------------------------------------
# pyproject's addopts run `--dist loadfile --no-loadscope-reorder`: with -n, each test module goes
# to one worker whole, so its module-scoped fixtures (often a whole virtual study) are built once,
# not once on each worker that gets some of its tests (`--dist load` splits modules). Modules are
# handed out in collection order, and modules with tests marked `slow` are collected first: the
# long ones start at once and the many short ones fill the other worker at the end, instead of
# one long module starting last and running alone. (`--dist loadgroup` with `xdist_group` marks
# would group finer, but pytest-xdist 3.8 sets `item._nodeid`, which pytest 9.2 no longer reads:
# the marks have no effect there.)


#
# Modules marked `realtime` (the online loop at its real cycle: they wait on the clock far more
# than they compute) are spread among the CPU-bound ones: one after every second CPU-bound module,
# so a worker running one has the other worker computing beside it. Side by side (they are
# neighbours alphabetically: test_online_*) both cores were mostly idle for their ~80 s.


def module_order(
    modules: list[Path], slow: set[Path], realtime: set[Path], every: int = 2
) -> list[Path]:
    """The order modules are handed to the workers: those with a slow test first, each
    ``realtime`` module after every ``every`` CPU-bound ones (collection order otherwise)."""
    cpu = [m for m in modules if m not in realtime]
    cpu.sort(key=lambda m: m not in slow)  # stable
    rt = [m for m in modules if m in realtime]
    rt.sort(key=lambda m: m not in slow)
    out: list[Path] = []
    for i, m in enumerate(cpu):
        out.append(m)
        if rt and i % every == 0:
            out.append(rt.pop(0))
    return out + rt


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    slow = {item.path for item in items if item.get_closest_marker("slow") is not None}
    realtime = {item.path for item in items if item.get_closest_marker("realtime") is not None}
    modules = list(dict.fromkeys(item.path for item in items))
    rank = {m: i for i, m in enumerate(module_order(modules, slow, realtime))}
    items.sort(key=lambda item: rank[item.path])  # stable: each module stays in order
