"""Compiled robot kernels built in the background on a fresh install.

numba builds a kernel on its first call (tens of seconds per module; minutes on a loaded
machine) and caches it on disk. Rather than make the first run wait, the ``"auto"`` engine asks
:func:`compiled_ready`: when the cache of the robot kernels (``vjm_numba``, ``fk_numba``,
``ik_numba``) is not there yet, it starts **one** detached process (``python -m
roboisf.robot.warm``) that builds them and answers False, so this run is served by the numpy
engine (same numbers to rounding, ≈ 25 % slower warm). A later process finds the cache and
runs compiled.

Safe by construction: one builder at a time per cache (an exclusive lock file, stale after
:data:`STALE_S`); a read-only or missing cache folder only means the builder's work is lost
(numba then compiles in memory; nothing else fails); the builder runs in its own session, so a
Ctrl-C of the user's command does not reach it, and with its stdio on ``/dev/null`` it never
writes to the user's terminal; numba writes its cache files by rename, so a concurrent reader
sees a whole file or none. ``ROBOISF_BACKGROUND_COMPILE=0`` switches this off (the first call
compiles in the foreground, as before); an explicit ``backend="numba"`` always compiles.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from roboisf.progress import background_build_notice, kernel_cached

__all__ = [
    "BUILD_WAIT",
    "ENV",
    "KERNEL_FILES",
    "STALE_S",
    "all_cached",
    "background_enabled",
    "build",
    "compiled_ready",
    "lock_path",
]

#: Environment switch: "0" compiles in the foreground on first use (no background builder).
ENV = "ROBOISF_BACKGROUND_COMPILE"
#: How long the background build takes, as the notice says it (measured: docs/robot.md, "First
#: run"): 26 s on the 2-core machine at load 0.8.
BUILD_WAIT = "about 30 s to 1 minute, once"
#: A builder's lock older than this [s] is taken as left by a killed builder.
STALE_S = 900.0

_HERE = Path(__file__).resolve().parent
#: The modules whose numba kernels the builder compiles (``cache=True``).
KERNEL_FILES = tuple(_HERE / f for f in ("vjm_numba.py", "fk_numba.py", "ik_numba.py"))

_started = False


def background_enabled() -> bool:
    """False when :data:`ENV` is "0" (compile in the foreground)."""
    return os.environ.get(ENV, "1").strip() != "0"


def lock_path() -> Path:
    """The builder's lock file: one per cache folder and per version of the kernel sources."""
    key = (
        os.environ.get("NUMBA_CACHE_DIR", "")
        + "|"
        + "|".join(f"{p}:{p.stat().st_mtime_ns}" for p in KERNEL_FILES if p.exists())
    )
    digest = hashlib.sha1(key.encode()).hexdigest()[:16]
    return Path(tempfile.gettempdir()) / f"roboisf-kernel-build-{digest}.lock"


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


def all_cached() -> bool:
    """True when numba holds a cache of every module of :data:`KERNEL_FILES`."""
    return all(kernel_cached(p) for p in KERNEL_FILES)


def compiled_ready() -> bool:
    """Whether the ``"auto"`` engine should run compiled in this process.

    True when the kernels are cached (or background building is off: :data:`ENV`). Else starts
    the background builder (at most once per process, and not while another holds the lock)
    and returns False: the numpy engine serves this run.
    """
    global _started
    if not background_enabled() or all_cached():
        return True
    if not _started:
        _started = True
        _spawn()
    return False


def _spawn() -> None:
    lock = lock_path()
    if not _take_lock(lock):
        return
    env = dict(os.environ)
    env[ENV] = "0"  # the builder compiles; it must not spawn builders itself
    try:
        subprocess.Popen(
            [sys.executable, "-m", "roboisf.robot.warm", str(lock)],
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
    background_build_notice("robot", BUILD_WAIT)


def build() -> None:
    """Compile (and so cache) the robot kernels by running them once on a few poses of a preset."""
    import numpy as np

    from roboisf.robot.ik import ik_toolpath
    from roboisf.robot.maps import stiffness_map
    from roboisf.robot.presets import list_robots, load_robot

    models = [load_robot(n) for n in list_robots()]
    model = next(m for m in models if m.stiffness is not None).with_backend("numba")
    mid = 0.5 * (model.q_min + model.q_max)
    q = mid + np.linspace(-0.2, 0.2, 4)[:, None] * (model.q_max - model.q_min) / 2
    model.vjm(q, np.ones(6), want_compliance=True, want_jacobian=True)
    model.tip_positions(q)
    smap = stiffness_map(model, n=3, half_width=0.1)
    del smap
    pts = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.02, 0.0, 0.0]])
    if model.default_placement is not None:
        ik_toolpath(model, pts, backend="numba")


def main(argv: list[str]) -> int:
    lock = Path(argv[0]) if argv else None
    try:
        build()
    except Exception:  # a build failure only means the next run compiles in the foreground
        return 1
    finally:
        if lock is not None:
            lock.unlink(missing_ok=True)
    return 0


if __name__ == "__main__":  # pragma: no cover - the background builder
    raise SystemExit(main(sys.argv[1:]))
