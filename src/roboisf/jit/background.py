"""Compiled kernels built in the background on a fresh install: no first run waits for numba.

numba builds a kernel on its first call (seconds to minutes per module, more on a loaded
machine) and caches it on disk. Every ``"auto"`` dispatch asks :func:`ready` with its kernel
group (:data:`GROUPS`): when the group's cache is there it runs compiled; when not, it answers
False — the numpy path serves this run (the same numbers to the tolerance each group's tests
state) — and starts **one** detached process (``python -m roboisf.jit.background``) that builds
*every* missing group. A later process finds the cache and runs compiled. The answer is taken
once per group and process, so one run never mixes engines for a group.

Safe by construction:

* one builder at a time per cache folder and version of the kernel sources (an exclusive lock
  file in the temp folder, stale after :data:`STALE_S`): concurrent commands, pytest-xdist
  workers and the demo's worker processes start at most one;
* the builder runs in its own session (a Ctrl-C of the user's command does not reach it), with
  its stdio on ``/dev/null`` (never writes to the user's terminal) and at a lower priority
  (:data:`NICE`: the user's command gets the CPU first), and it starts building only once
  the command that started it has ended (:data:`DEFER_S` at most: beside the first run it
  slowed that run by half); numba writes its cache files
  by rename, so a concurrent reader sees a whole file or none;
* a builder that fails — or builds without leaving a cache (a read-only cache folder) — leaves
  a failure marker (:func:`failure_path`, keyed by the cache folder, the kernel sources' versions
  and numba's version) holding the reason; while it is there no builder is started again and the
  notice says so. To retry, delete the marker, or run once with ``ROBOISF_BACKGROUND_COMPILE=0``
  (the kernels then compile in the foreground and any error shows);
* no writable temp folder: no lock, no builder, the numpy path serves every run.

``ROBOISF_BACKGROUND_COMPILE=0`` (:data:`ENV`) switches this off: :func:`ready` is then True
whenever numba is installed and the first call compiles in the foreground, as before.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from roboisf.jit.shim import HAVE_NUMBA, NUMBA_ENV, kernel_cached, numba_version_installed
from roboisf.progress import notice_once

__all__ = [
    "BUILD_WAIT",
    "DEFER_S",
    "ENV",
    "GROUPS",
    "STALE_S",
    "Group",
    "background_enabled",
    "build_groups",
    "build_missing",
    "failure_path",
    "group_cached",
    "lock_path",
    "main",
    "ready",
    "wait_for",
]

#: Environment switch: "0" compiles in the foreground on first use (no background builder).
ENV = "ROBOISF_BACKGROUND_COMPILE"
#: How long the background build of all groups takes, as the notice says it (measured:
#: docs/speed.md).
BUILD_WAIT = "about 30 s to 2 minutes, once, after this run"
#: Longest wait [s] of a builder for the command that started it to end: a long-running one
#: (a notebook, ``roboisf online`` over a whole part) does not defer the build forever.
DEFER_S = 600.0
#: A builder's lock older than this [s] is taken as left by a killed builder.
STALE_S = 900.0

_ROOT = Path(__file__).resolve().parents[1]  # the roboisf package folder


@dataclass(frozen=True)
class Group:
    """A kernel group: the modules whose ``cache=True`` kernels it needs (dotted names, found
    by path without importing them) and ``build`` ("module:function"), a function that compiles
    them by running them once on a small input; ``native``: the modules whose C forms
    (:mod:`roboisf.jit.native`), when all are built, serve every call the group's callers make
    (then the group runs compiled without numba)."""

    modules: tuple[str, ...]
    build: str
    lane: int = 0
    native: tuple[str, ...] = ()

    def files(self) -> tuple[Path, ...]:
        """The modules' source files."""
        return tuple(_ROOT.joinpath(*m.split(".")[1:]).with_suffix(".py") for m in self.modules)


#: Every compiled kernel of roboisf, by group, in build order. A kernel module (one that
#: decorates with :func:`roboisf.jit.njit`) belongs to a group here and has its ``build()``
#: (tests/test_jit.py checks both). ``lane``: the builder builds each lane's groups in order in
#: one process and the lanes side by side, one process per core (:func:`build_missing`); a
#: group that calls another's kernels goes in its lane after it, where they are compiled
#: already (alone, "online" took 4.1 s and "sync" 2.6 s; after "robot" 0.03 and 0.01 s), and
#: groups sharing a module share a lane (tests/test_jit.py). The two lanes: ≈ 8.5 and 6.1 s of
#: compiling on the machine of docs/speed.md.
GROUPS: dict[str, Group] = {
    "mesh": Group(
        (
            "roboisf.parts.mesh_kernel",
            "roboisf.parts.axisym_kernel",
            "roboisf.parts.pyramid_kernel",
        ),
        "roboisf.parts.mesh_kernel:build",
        native=(
            "roboisf.parts.mesh_kernel",
            "roboisf.parts.axisym_kernel",
            "roboisf.parts.pyramid_kernel",
        ),
    ),
    "scan": Group(
        ("roboisf.parts.mesh_kernel", "roboisf.scan.knn_kernel", "roboisf.scan.toolpath_kernel"),
        "roboisf.scan.toolpath_kernel:build",
        native=(
            "roboisf.parts.mesh_kernel",
            "roboisf.scan.knn_kernel",
            "roboisf.scan.toolpath_kernel",
        ),
    ),
    "robot": Group(
        ("roboisf.robot.vjm_numba", "roboisf.robot.fk_numba", "roboisf.robot.ik_numba"),
        "roboisf.robot.vjm_numba:build",
        lane=1,
        native=("roboisf.robot.vjm_kernel",),  # FK, VJM, IK, plan's pass, the margin: one library
    ),
    "online": Group(
        ("roboisf.online.kernel",),
        "roboisf.online.kernel:build",
        lane=1,
        native=("roboisf.online.kernel",),  # its C form: online_kernel.c (kernel.NATIVE)
    ),
    "sync": Group(
        ("roboisf.sync.position_kernel",),
        "roboisf.sync.position_kernel:build",
        lane=1,
        native=("roboisf.sync.position_kernel",),
    ),
    "forcelog": Group(
        ("roboisf.logs.forcelog_kernel",),
        "roboisf.logs.forcelog_kernel:build",
        lane=1,
        native=("roboisf.logs.forcelog_kernel",),
    ),
}

_decided: dict[str, bool] = {}
_started = False
_decide = threading.Lock()  # the scan's worker threads ask too


#: The engines a ``backend=`` argument accepts.
BACKENDS = ("auto", "numba", "numpy")


def check_backend(backend: str, *, field: str = "backend", have_numba: bool | None = None) -> str:
    """``backend`` checked: one of :data:`BACKENDS`, and "numba" only with numba installed
    (``have_numba``: the caller's own flag, default :data:`~roboisf.jit.HAVE_NUMBA`)."""
    from roboisf.errors import InputError

    if backend not in BACKENDS:
        raise InputError(
            f"backend must be 'auto', 'numba' or 'numpy', got {backend!r}", field=field
        )
    if backend == "numba" and not (HAVE_NUMBA if have_numba is None else have_numba):
        raise InputError(
            f"backend 'numba' needs numba, which is switched off ({NUMBA_ENV}=0) or does not "
            "import here (pip install numba)",
            field=field,
        )
    return backend


def background_enabled() -> bool:
    """False when :data:`ENV` is "0" (compile in the foreground)."""
    return os.environ.get(ENV, "1").strip() != "0"


def group_cached(name: str) -> bool:
    """True when numba holds a cache of every module of group ``name``."""
    return all(kernel_cached(p) for p in GROUPS[name].files())


def _key() -> str:
    files = sorted({p for g in GROUPS.values() for p in g.files()})
    return (
        os.environ.get("NUMBA_CACHE_DIR", "")
        + "|"
        + "|".join(f"{p}:{p.stat().st_mtime_ns}" for p in files if p.exists())
    )


def _digest(key: str) -> str:
    return hashlib.sha1(key.encode()).hexdigest()[:16]


def lock_path() -> Path:
    """The builder's lock file: one per cache folder and version of the kernel sources."""
    return Path(tempfile.gettempdir()) / f"roboisf-kernel-build-{_digest(_key())}.lock"


def failure_path() -> Path:
    """The failure marker a builder leaves: keyed by the cache folder, the kernel sources'
    versions and numba's version (a new numba or an edited kernel tries again)."""
    key = _key() + "|numba " + (numba_version_installed() or "?")
    return Path(tempfile.gettempdir()) / f"roboisf-kernel-build-{_digest(key)}.failed"


def _take_lock(path: Path) -> bool:
    """Create ``path`` exclusively (a stale one is replaced); False while another builder has it."""
    for _ in range(2):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                if time.time() - path.stat().st_mtime < STALE_S:
                    return False
                path.unlink()
            except OSError:
                return False
            continue
        except OSError:
            return False  # no writable temp folder: no builder
        os.write(fd, str(os.getpid()).encode())
        os.close(fd)
        return True
    return False


def ready(group: str) -> bool:
    """Whether an ``"auto"`` dispatch of kernel ``group`` (a key of :data:`GROUPS`) runs
    compiled in this process.

    True when the group's C forms are built (:func:`native_ready`: no numba at all). Else
    False without numba; True when the group is cached, or when background building is off
    (:data:`ENV`: the first call compiles in the foreground). Else False — the numpy path
    serves this run — after starting the background builder of every missing group (at most
    once per process, not while another builder holds the lock, not after a failed build:
    :func:`failure_path`). The answer is kept for the rest of the process.
    """
    if group not in GROUPS:
        raise KeyError(f"unknown kernel group {group!r}; known: {', '.join(GROUPS)}")
    if native_ready(group):
        return True
    if not HAVE_NUMBA:
        return False
    with _decide:
        if group not in _decided:
            ok = not background_enabled() or group_cached(group)
            if not ok:
                _start()
            _decided[group] = ok
        return _decided[group]


def native_ready(group: str) -> bool:
    """Whether the C forms of group ``group`` (:attr:`Group.native`) are all built and fresh:
    its callers then run compiled, without numba (each module's ``_c()`` loads its library)."""
    mods = GROUPS[group].native
    if not mods:
        return False
    import importlib

    return all(getattr(importlib.import_module(m), "_c", lambda: None)() is not None for m in mods)


def _start() -> None:
    global _started
    if _started:
        return
    _started = True
    failed = failure_path()
    if failed.exists():
        notice_once(
            "roboisf's compiled kernels (numba) failed to build in the background before "
            f"(the reason is in {failed}); this run uses the numpy engine. To retry, delete "
            f"that file, or run once with {ENV}=0 to build them in the foreground"
        )
        return
    lock = lock_path()
    if not _take_lock(lock):
        return  # another process is building them (or no temp folder): numpy serves this run
    env = dict(os.environ)
    env[ENV] = "0"  # the builder compiles; it must not spawn builders itself
    try:
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "roboisf.jit.background",
                str(lock),
                str(failed),
                str(os.getpid()),  # builds once this process has ended (DEFER_S at most)
            ],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,  # a Ctrl-C of the user's command does not stop the build
            close_fds=True,
            env=env,
        )
    except OSError:
        lock.unlink(missing_ok=True)
        return
    notice_once(
        f"building roboisf's compiled kernels (numba) in the background ({BUILD_WAIT}); "
        "this run uses the numpy engine, later runs the compiled one"
    )


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - someone else's process now holds the pid
        return True
    return True


def wait_for(
    pid: int,
    lock: Path | None,
    *,
    limit: float = DEFER_S,
    poll: float = 0.25,
    touch_every: float = 60.0,
) -> bool:
    """Wait until process ``pid`` has ended, at most ``limit`` s; True if it has. The lock's
    time is refreshed every ``touch_every`` s meanwhile, so no other process takes it for a
    killed builder's (:data:`STALE_S`)."""
    end = time.monotonic() + limit
    touched = time.monotonic()
    while _alive(pid):
        now = time.monotonic()
        if now >= end:
            return False
        if lock is not None and now - touched >= touch_every:
            try:
                os.utime(lock)
            except OSError:  # the lock is gone (removed by hand): wait on; main() unlinks it
                pass  # with missing_ok, and at worst a second builder builds beside this one
            touched = now
        time.sleep(poll)
    return True


def build_missing(jobs: int | None = None, *, skip_native: bool = False) -> list[str]:
    """Build every group of :data:`GROUPS` not cached yet; the failures, one line per group.
    ``skip_native``: not the groups whose C forms serve them here (:func:`native_ready`) — the
    background builder's choice, and a wheel's build step's (an editable install builds every
    group: :mod:`roboisf.jit.prebuild`).

    The lanes (:attr:`Group.lane`) are built side by side, ``jobs`` processes at most (default:
    the cores this process may use, :func:`roboisf.jit.cores`): this one builds the first, a
    spawned process each other (lanes beyond ``jobs`` join them in turn). One job, or one lane
    missing: everything here, in order."""
    from roboisf.jit.threads import cores

    by_lane: dict[int, list[str]] = {}
    for name, group in GROUPS.items():
        if not group_cached(name) and not (skip_native and native_ready(name)):
            by_lane.setdefault(group.lane, []).append(name)
    shares = lane_shares([by_lane[k] for k in sorted(by_lane)], cores() if jobs is None else jobs)
    if len(shares) == 1:
        return build_groups(shares[0])
    n = len(shares)
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    # by its module's name: the builder runs this file as __main__ (python -m)
    from roboisf.jit.background import build_groups as in_child

    with ProcessPoolExecutor(n - 1, mp_context=multiprocessing.get_context("spawn")) as pool:
        others = [(names, pool.submit(in_child, names)) for names in shares[1:]]
        failures = build_groups(shares[0])
        for names, future in others:
            try:
                failures += future.result()
            except Exception as e:  # the process died (killed, out of memory)
                failures += [f"{name}: its build process failed: {e!r}" for name in names]
    return failures


def lane_shares(lanes: list[list[str]], jobs: int) -> list[list[str]]:
    """The groups of ``lanes`` (each in build order) dealt to at most ``jobs`` processes: lane
    i to process i mod n, each process's lanes one after the other ([[]]: no lane)."""
    n = max(1, min(jobs, len(lanes)))
    if not lanes:
        return [[]]
    return [[name for lane in lanes[i::n] for name in lane] for i in range(n)]


def build_groups(names: list[str]) -> list[str]:
    """Build the groups ``names`` in order in this process; the failures, one line per group."""
    from roboisf.jit import native

    failures = []
    for name in names:
        module, function = GROUPS[name].build.split(":")
        try:
            with native.suspended():  # the build runs the numba kernels, not their C forms
                getattr(importlib.import_module(module), function)()
        except Exception as e:
            failures.append(f"{name}: {type(e).__name__}: {e}")
            continue
        if not group_cached(name):
            failures.append(
                f"{name}: built, but numba left no cache (is the cache folder writable? "
                "NUMBA_CACHE_DIR)"
            )
    return failures


#: The builder's niceness: background work, it gives the CPU to the user's command first (on 2
#: cores the first run and the builder otherwise share them evenly).
NICE = 10


def _lower_priority() -> None:
    try:
        os.nice(NICE)
    except (AttributeError, OSError):  # pragma: no cover - not on this platform / not allowed
        pass


def main(argv: list[str]) -> int:
    """The builder: ``LOCK [FAILURE_MARKER [PID]]``. Waits for process ``PID`` (the command
    that started it) to end — at most :data:`DEFER_S` — then builds the missing groups, writes
    the marker (atomically) if any failed, and removes the lock in every case.

    Why wait: a build beside the first run slowed it by half even at a lower priority (the
    first `roboisf demo` on a cold cache 33.6 s with the builder beside it, 22.6 s without, 16.5
    s warm, 2 vCPUs: the compiler's CPU and memory traffic share the cores the run's own
    threads and processes use)."""
    lock = Path(argv[0]) if argv else None
    marker = Path(argv[1]) if len(argv) > 1 else None
    try:
        _lower_priority()
        if len(argv) > 2:
            wait_for(int(argv[2]), lock)
        # not the groups the C forms serve: a run asks numba for them only with ROBOISF_NATIVE=0
        # (inherited by this process, which then builds them too)
        failures = build_missing(skip_native=True)
        if failures and marker is not None:
            tmp = marker.with_name(marker.name + f".{os.getpid()}.tmp")
            tmp.write_text("\n".join(failures) + "\n", encoding="utf-8")
            os.replace(tmp, marker)
        return 1 if failures else 0
    finally:
        if lock is not None:
            lock.unlink(missing_ok=True)


if __name__ == "__main__":  # pragma: no cover - the background builder
    raise SystemExit(main(sys.argv[1:]))
