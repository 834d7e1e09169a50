"""Where roboisf may write, and how an output survives errors, interruptions and a second run.

The output policy of every command (docs/conventions.md, "Outputs"):

* A folder roboisf writes carries a marker, :data:`MARKER` (``.roboisf-output.json``): the
  command, the roboisf version, the time and the list of files it wrote (with size and
  modification time). ``-o DIR`` is accepted when DIR does not exist, is empty, or holds the
  marker of the same command; any other folder is refused unless ``overwrite``. Even then only the
  files listed in the marker are replaced or removed: a file roboisf did not write (or that was
  changed after roboisf wrote it) is never touched.
* The location is checked before any computation (:func:`claim_output_dir`,
  :func:`claim_output_file`): not the working folder or one of its parents, not an existing file
  where a folder is expected (or the reverse), a writable parent that is a folder, never equal
  to, inside or around an input.
* A lock file next to the output (``.NAME.roboisf-lock``, ``fcntl.flock`` with the holder's pid)
  makes a second run into the same output fail at once; the kernel drops the lock of a dead run.
* A folder is built in a sibling ``.NAME.staging.*`` folder and moved into place only when
  complete; stale ``.NAME.staging.*``/``.NAME.old.*`` folders of dead runs (recognised by the
  :data:`STAGING_MARKER` inside, with the pid) are removed when the next run starts.
* SIGINT, SIGTERM and SIGHUP (handlers installed by :func:`signal_handlers`; SIGHUP unless
  ignored by ``nohup``) raise :class:`Interrupted`, which unwinds the stack so the staging
  folder is removed and the previous results stay intact; the final moves into place are never
  cut in half (the signal is held until they are done).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import signal
import stat
import tempfile
import threading
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from types import FrameType
from typing import Any

from roboisf.errors import InputError, ResourceError

__all__ = [
    "MARKER",
    "SIGNAL_OUTCOMES",
    "STAGING_MARKER",
    "Interrupted",
    "OutputClaim",
    "claim_output_dir",
    "claim_output_file",
    "deferred_signals",
    "environment_error",
    "final_location",
    "mark_written",
    "output_session",
    "read_marker",
    "signal_handlers",
    "staged_output_dir",
]

#: Marker file in every output folder roboisf writes.
MARKER = ".roboisf-output.json"
#: Marker inside staging and backup folders: who made them (pid), so a later run can remove them.
STAGING_MARKER = ".roboisf-staging.json"
_MARKER_FORMAT = "roboisf-output/1"


# --------------------------------------------------------------------------------------------
# signals


class Interrupted(BaseException):
    """SIGINT, SIGTERM or SIGHUP arrived; raised from the signal handler to unwind the stack.

    A :class:`BaseException` so ``except Exception`` blocks do not swallow it. ``exit_code`` is
    the shell convention 128 + signal number (130 SIGINT, 143 SIGTERM, 129 SIGHUP).
    """

    def __init__(self, signum: int) -> None:
        self.signum = int(signum)
        self.exit_code = 128 + self.signum
        super().__init__(signal.Signals(self.signum).name)


_defer_depth = 0
_pending: int | None = None


#: How a command ended by a signal, by its exit code (128 + the signal's number): the line
#: every command prints (:func:`roboisf.cli.main.main`) and the online loop's stop reason.
SIGNAL_OUTCOMES = {
    129: "hung up (SIGHUP: the terminal closed)",
    130: "interrupted (SIGINT)",
    143: "terminated (SIGTERM)",
}


def _handler(signum: int, frame: FrameType | None) -> None:
    global _pending
    if _defer_depth > 0:
        _pending = signum
        return
    raise Interrupted(signum)


#: The standard streams' descriptors that were terminals when :func:`signal_handlers` began:
#: after a hang-up they are pointed at ``/dev/null`` (:func:`_hangup`).
_terminal_fds: list[int] = []


def _hangup(signum: int, frame: FrameType | None) -> None:
    """SIGHUP: the terminal is gone (an ssh session dropped, its window closed). The standard
    streams that were that terminal now write to ``/dev/null`` — a write to a hung-up terminal
    fails (EIO), and the unwinding's own lines (the online loop's status during its ramp to
    zero, the summary) must not stop it — then the command unwinds as for SIGTERM."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
    except OSError:  # pragma: no cover - no /dev/null
        null = -1
    if null >= 0:
        for fd in _terminal_fds:
            with contextlib.suppress(OSError):
                os.dup2(null, fd)
        os.close(null)
    _handler(signum, frame)


@contextlib.contextmanager
def deferred_signals() -> Iterator[None]:
    """Hold SIGINT/SIGTERM/SIGHUP (when :func:`signal_handlers` is active) until the block ends.

    For the few renames that put an output into place and for clean-up: they run to the end, then
    the held signal raises :class:`Interrupted`.
    """
    global _defer_depth, _pending
    _defer_depth += 1
    try:
        yield
    finally:
        _defer_depth -= 1
        if _defer_depth == 0 and _pending is not None:
            signum, _pending = _pending, None
            raise Interrupted(signum)


@contextlib.contextmanager
def signal_handlers() -> Iterator[None]:
    """Turn SIGINT, SIGTERM and SIGHUP into :class:`Interrupted` for the duration (main thread
    only). SIGHUP (POSIX) only where it was not ignored when the process started: a command run
    under ``nohup`` goes on when its terminal closes, as the user asked; otherwise a hang-up
    unwinds like SIGTERM (outputs discarded whole, ``roboisf online``'s correction ramped to
    zero), with the terminal's streams silenced first (:func:`_hangup`)."""
    global _terminal_fds
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handlers: dict[int, Any] = {signal.SIGINT: _handler, signal.SIGTERM: _handler}
    hup = getattr(signal, "SIGHUP", None)
    if hup is not None and signal.getsignal(hup) is not signal.SIG_IGN:
        handlers[hup] = _hangup
    previous = {s: signal.getsignal(s) for s in handlers}
    terminal_fds = _terminal_fds
    _terminal_fds = [fd for fd in (1, 2) if _isatty(fd)]
    for s, h in handlers.items():
        signal.signal(s, h)
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
        _terminal_fds = terminal_fds


def _isatty(fd: int) -> bool:
    try:
        return os.isatty(fd)
    except OSError:
        return False


# --------------------------------------------------------------------------------------------
# claims: checked location + lock, for the lifetime of a command


@dataclass
class OutputClaim:
    """An output location checked and locked for one command (see :func:`claim_output_dir`)."""

    path: Path
    kind: str  # "dir" or "file"
    command: str
    overwrite: bool
    existed: bool
    committed: bool = False
    shown: str = ""  # the path as the user gave it, for messages
    _lock: _Lock | None = field(default=None, repr=False)

    def release(self) -> None:
        """Drop the lock (idempotent); without a result, remove the empty parents made for it."""
        if self._lock is not None:
            self._lock.release(remove_made=not self.committed)
            self._lock = None

    def outcome(self) -> str:
        """What happened to this output, for the one line printed after an interruption."""
        name = self.shown or str(self.path)
        if self.committed:
            return f"{name} was written completely"
        kept = " (its previous contents are intact)" if self.existed else ""
        return f"nothing written to {name}{kept}"


class _Session:
    def __init__(self) -> None:
        self.claims: list[OutputClaim] = []

    def find(self, path: Path) -> OutputClaim | None:
        for c in self.claims:
            if c.path == path:
                return c
        return None


_sessions: list[_Session] = []


@contextlib.contextmanager
def output_session() -> Iterator[_Session]:
    """Own the claims made inside the block and release their locks at its end (CLI ``main``)."""
    s = _Session()
    _sessions.append(s)
    try:
        yield s
    finally:
        _sessions.remove(s)
        for c in s.claims:
            c.release()


def _active_claim(path: Path) -> OutputClaim | None:
    for s in reversed(_sessions):
        c = s.find(path)
        if c is not None:
            return c
    return None


def _register(claim: OutputClaim) -> None:
    if _sessions:
        _sessions[-1].claims.append(claim)
    else:  # outside the CLI: held until the process ends
        import atexit

        atexit.register(claim.release)


def _resolve(path: str | Path) -> Path:
    return Path(os.path.abspath(os.path.expanduser(path))).resolve()


def _check_location(out: Path, shown: str | Path, kind: str, inputs: Sequence[str | Path]) -> None:
    """Checks common to folders and files; ``out`` is resolved, ``shown`` is what the user gave."""
    what = "folder" if kind == "dir" else "file"
    cwd = Path.cwd().resolve()
    if kind == "dir" and (out == cwd or out in cwd.parents):
        raise InputError(
            "the output folder may not be the working folder or one of its parents; "
            "give a new folder, e.g. -o results",
            file=shown,
        )
    if out.parent == out:
        raise InputError(f"the file system root is not an output {what}", file=shown)
    _check_name_lengths(out, shown)
    if out.is_symlink():
        raise InputError(f"is a symbolic link; give a plain output {what}", file=shown)
    if out.exists():
        if kind == "dir" and not out.is_dir():
            raise InputError(
                "exists and is not a folder; this command writes a folder (give a folder name)",
                file=shown,
            )
        if kind == "file" and out.is_dir():
            raise InputError(
                "is a folder; this command writes a file (give a file name)", file=shown
            )
    # nearest existing ancestor must be a writable folder
    anc = out.parent
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir():
        raise InputError(f"cannot create the output: {anc} is a file, not a folder", file=shown)
    if not os.access(anc, os.W_OK | os.X_OK):
        raise InputError(f"cannot write the output: no write permission in {anc}", file=shown)
    if out.exists() and kind == "dir" and not os.access(out, os.W_OK | os.X_OK):
        raise InputError("cannot write the output: no write permission in it", file=shown)
    for item in inputs:
        inp = _resolve(item)
        if inp == out:
            raise InputError(
                "the output is an input of this command (roboisf never overwrites an input); "
                "choose another -o",
                file=shown,
            )
        if inp in out.parents:
            raise InputError(
                f"the output would land inside the input {item}; choose a -o outside it",
                file=shown,
            )
        if kind == "dir" and out in inp.parents:
            raise InputError(
                f"the output folder contains the input {item}; choose a -o that holds no input",
                file=shown,
            )


#: characters roboisf adds to an output's name for its siblings: the lock ``.NAME.roboisf-lock``,
#: the staging folder ``.NAME.staging.XXXXXXXX`` and a temporary file ``.NAME.XXXXXXXX.parquet``
_SIBLING_EXTRA = 24


def _name_max(anc: Path) -> tuple[int, int]:
    """(longest file name, longest path) in bytes on the file system holding ``anc``."""
    try:
        return os.pathconf(anc, "PC_NAME_MAX"), os.pathconf(anc, "PC_PATH_MAX")
    except (OSError, ValueError, AttributeError):  # pragma: no cover - not POSIX
        return 255, 4096


def _check_name_lengths(out: Path, shown: str | Path) -> None:
    """Refuse an output whose name (or a folder to create for it) the file system cannot hold,
    with roboisf's lock and staging siblings, before anything is created (ENAMETOOLONG)."""
    anc = out.parent
    while True:
        try:
            if anc.exists():
                break
        except OSError:
            pass
        anc = anc.parent
    name_max, path_max = _name_max(anc)
    for i, part in enumerate(out.parts[1:], start=1):
        extra = _SIBLING_EXTRA if i == len(out.parts) - 1 else 0
        n = len(os.fsencode(part))
        if n + extra > name_max:
            limit = name_max - extra
            raise ResourceError(
                f"the name {part[:40]}… is {n} bytes long; the file system allows {name_max} per "
                f"name ({limit} for an output, roboisf adds its lock and staging suffixes): "
                "choose a shorter name",
                file=shown if len(str(shown)) <= 120 else f"{str(shown)[:60]}…",
            )
    if len(os.fsencode(str(out))) + _SIBLING_EXTRA + 32 > path_max:
        raise ResourceError(
            f"the path is {len(os.fsencode(str(out)))} bytes long; the file system allows "
            f"{path_max} in all: choose a shorter path",
            file=f"{str(shown)[:60]}…",
        )


def claim_output_dir(
    path: str | Path,
    command: str,
    *,
    overwrite: bool = False,
    inputs: Sequence[str | Path] = (),
) -> OutputClaim:
    """Check ``path`` as the output folder of ``command`` and lock it, before any computation.

    Parameters
    ----------
    path
        The ``-o`` folder.
    command
        The command name recorded in the marker (``"analyze"``, ``"demo"`` …).
    overwrite
        Accept a non-empty folder that is not a result of ``command``: the files of a previous
        roboisf result listed in its marker are replaced, everything else is kept as it is.
    inputs
        Files and folders the command reads: the output may not be, lie in, or contain one.

    Raises
    ------
    InputError
        The location is refused (message names the folder and why); or another run holds it.
    """
    out = _resolve(path)
    existing = _active_claim(out)
    if existing is not None:
        return existing
    claim = _claim_dir(out, path, command, overwrite, inputs)
    _register(claim)
    return claim


def _claim_dir(
    out: Path, shown: str | Path, command: str, overwrite: bool, inputs: Sequence[str | Path]
) -> OutputClaim:
    _check_location(out, shown, "dir", inputs)
    # lock first, then look inside: a run finishing meanwhile cannot change what was checked
    lock = _Lock.acquire(out, shown, command)
    try:
        existed = out.is_dir()
        if existed:
            _check_previous(out, shown, command, overwrite)
        _clean_stale(out)
    except BaseException:
        lock.release()
        raise
    return OutputClaim(out, "dir", command, overwrite, existed, shown=str(shown), _lock=lock)


def claim_output_file(
    path: str | Path,
    command: str,
    *,
    overwrite: bool = False,
    inputs: Sequence[str | Path] = (),
) -> OutputClaim:
    """Check ``path`` as an output file of ``command`` and lock it, before any computation.

    An existing file is replaced only with ``overwrite`` (roboisf cannot tell whether it wrote a
    loose file); never when it is an input. Same location checks and lock as
    :func:`claim_output_dir`.
    """
    out = _resolve(path)
    existing = _active_claim(out)
    if existing is not None:
        return existing
    _check_location(out, path, "file", inputs)
    existed = out.exists()
    if existed and not overwrite:
        raise InputError(
            "exists; pass --overwrite to replace it (roboisf never replaces a file silently)",
            file=path,
        )
    lock = _Lock.acquire(out, path, command)
    claim = OutputClaim(out, "file", command, overwrite, existed, shown=str(path), _lock=lock)
    _register(claim)
    return claim


def mark_written(path: str | Path) -> None:
    """Record that the claimed output ``path`` is complete (for the interruption message)."""
    if not _sessions:
        return
    c = _active_claim(_resolve(path))
    if c is not None:
        c.committed = True


# --------------------------------------------------------------------------------------------
# environment errors: what the machine refused, as one line naming the path and what to do

#: errno → what to do (the operating system's own text comes first)
_ADVICE = {
    errno.ENOSPC: "free space on that disk or choose a -o on another one",
    errno.EDQUOT: "your disk quota is used up: free space or choose a -o on another disk",
    errno.ENAMETOOLONG: "choose a shorter name (most file systems allow 255 bytes per name)",
    errno.EACCES: "choose a location you may write to (or read, for an input), or ask for "
    "the permission",
    errno.EPERM: "choose a location you may write to, or ask for the permission",
    errno.EROFS: "the disk is read-only: choose a -o on a writable disk",
    errno.EIO: "the disk reported an input/output error: check it, or use another disk",
    errno.EMFILE: "too many open files: raise the limit (ulimit -n) or close other programs",
    errno.ENFILE: "too many open files on this machine: close other programs and run again",
    errno.EFBIG: "the file is larger than the file system or a size limit (ulimit -f) allows: "
    "choose another disk or raise the limit",
    errno.ENOENT: "check the name: the file or folder does not exist (any more)",
    errno.ENOTDIR: "a part of the path is a file, not a folder: check the path",
    errno.EISDIR: "a folder is where a file is expected: check the path",
    errno.ELOOP: "the path has a symbolic-link loop: check the path",
    errno.EHOSTUNREACH: "check the address and the network cable/route to the device",
    errno.ENETUNREACH: "check the network settings: the device's network cannot be reached",
    errno.ECONNREFUSED: "nothing listens at that address and port: start the device or check "
    "the address",
    errno.ETIMEDOUT: "the device did not answer in time: check it is on and on the network",
}


def environment_error(e: OSError | MemoryError, shown: str | Path | None = None) -> ResourceError:
    """``e`` (an error of the operating system: a full disk, a name too long, no permission, an
    unreachable host, no memory) as a one-line :class:`ResourceError` naming the path and what
    to do; when the error names no path, the outputs claimed by the running command are named
    with what happened to them (nothing written, previous contents intact)."""
    if isinstance(e, MemoryError):
        return ResourceError(
            "not enough memory for this run: close other programs, or make the input smaller "
            "(a coarser step or spacing, fewer points)",
            file=shown,
        )
    import socket

    what = (e.strerror or str(e) or type(e).__name__).rstrip(".")
    if isinstance(e, socket.gaierror):
        what = f"the host name cannot be resolved ({what})"
        advice = "check the address (a name or four numbers 0–255, e.g. 192.168.125.1)"
    else:
        advice = _ADVICE.get(e.errno or -1, "")
    where = shown
    for name in (e.filename, e.filename2):
        if name is not None:
            where = os.fsdecode(name) if isinstance(name, bytes) else str(name)
            break
    outcome = ""
    if _sessions and _sessions[-1].claims:
        claims = _sessions[-1].claims
        if where is None:
            where = claims[0].shown or str(claims[0].path)
        outcome = "; ".join(c.outcome() for c in claims if not c.committed)
    if where is not None and len(str(where)) > 120:
        where = f"{str(where)[:60]}…{str(where)[-40:]}"
    msg = what[0].lower() + what[1:] if what[1:2].islower() else what
    if advice:
        msg += f"; {advice}"
    if outcome:
        msg += f" ({outcome})"
    return ResourceError(msg, file=where)


# --------------------------------------------------------------------------------------------
# the marker


def read_marker(folder: str | Path) -> dict[str, Any] | None:
    """The parsed marker of ``folder``, or ``None`` when it has none or it is not roboisf's."""
    p = Path(folder) / MARKER
    try:
        if not p.is_file() or p.is_symlink() or p.stat().st_size > 50_000_000:
            return None
        data = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    if (
        not isinstance(data, dict)
        or data.get("format") != _MARKER_FORMAT
        or not isinstance(data.get("command"), str)
        or not isinstance(data.get("files"), list)
    ):
        return None
    return data


def _safe_relpath(rel: object) -> PurePosixPath | None:
    if not isinstance(rel, str) or not rel or "\\" in rel or "\x00" in rel:
        return None
    p = PurePosixPath(rel)
    if p.is_absolute() or any(part in ("", ".", "..") for part in p.parts):
        return None
    if p.parts[0] == MARKER and len(p.parts) == 1:
        return None
    return p


@dataclass
class _Previous:
    ours: list[PurePosixPath]  # files roboisf wrote, unchanged since
    changed: list[PurePosixPath]  # listed, but changed afterwards: the user's now


def _previous_files(folder: Path, marker: dict[str, Any] | None) -> _Previous:
    """Files listed in ``marker`` that are still what roboisf wrote (no symlinks, same stat)."""
    prev = _Previous([], [])
    if marker is None:
        return prev
    for entry in marker["files"]:
        if not isinstance(entry, dict):
            continue
        rel = _safe_relpath(entry.get("path"))
        if rel is None:
            continue
        cur = folder
        ok = True
        for part in rel.parts:
            cur = cur / part
            try:
                st = os.lstat(cur)
            except OSError:
                ok = False
                break
            if stat.S_ISLNK(st.st_mode):
                ok = False
                break
        if not ok or not stat.S_ISREG(st.st_mode):
            continue
        if entry.get("size") == st.st_size and entry.get("mtime_ns") == st.st_mtime_ns:
            prev.ours.append(rel)
        else:
            prev.changed.append(rel)
    return prev


def _check_previous(out: Path, shown: str | Path, command: str, overwrite: bool) -> None:
    try:
        entries = [e.name for e in os.scandir(out)]
    except OSError as e:
        raise InputError(f"cannot read the output folder: {e.strerror}", file=shown) from None
    if not entries:
        return
    marker = read_marker(out)
    if marker is None:
        if not overwrite:
            raise InputError(
                "is not empty and is not a roboisf result; give a new or empty folder, or "
                "--overwrite to write into it (files roboisf did not write are kept)",
                file=shown,
            )
        return
    if marker["command"] != command and not overwrite:
        raise InputError(
            f"holds the result of `roboisf {marker['command']}`, not of `roboisf {command}`; "
            "give another folder, or --overwrite to replace that result",
            file=shown,
        )
    prev = _previous_files(out, marker)
    if prev.changed:
        raise InputError(
            f"{prev.changed[0]} was changed after roboisf wrote it; move it out of the folder "
            "first (roboisf never replaces a file it did not write)",
            file=shown,
        )


def _marker_data(command: str, folder: Path, files: Iterable[PurePosixPath]) -> dict[str, Any]:
    from roboisf import __version__

    listed = []
    for rel in sorted(files):
        st = os.lstat(folder / rel)
        listed.append({"path": str(rel), "size": st.st_size, "mtime_ns": st.st_mtime_ns})
    return {
        "format": _MARKER_FORMAT,
        "command": command,
        "version": __version__,
        "written_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "files": listed,
    }


# --------------------------------------------------------------------------------------------
# lock


class _Lock:
    """``fcntl.flock`` on ``.NAME.roboisf-lock`` next to the output; holds the pid and command.

    Without ``fcntl`` (or on a file system that refuses flock) the lock file itself is the lock:
    created with ``O_CREAT | O_EXCL``; one left by a dead pid is taken over.
    """

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self.fd: int | None = fd
        self.made: list[Path] = []  # parent folders created for the output, outermost first

    @staticmethod
    def lock_path(out: Path) -> Path:
        return out.parent / f".{out.name}.roboisf-lock"

    @classmethod
    def acquire(cls, out: Path, shown: str | Path, command: str) -> _Lock:
        missing = [p for p in reversed(out.parents) if not p.exists()]
        lock = cls._acquire(out, shown, command)
        lock.made = [p for p in missing if p.is_dir()]
        return lock

    @classmethod
    def _acquire(cls, out: Path, shown: str | Path, command: str) -> _Lock:
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX
            return cls._acquire_excl(out, shown, command)
        lp = cls.lock_path(out)
        for _ in range(20):
            try:
                out.parent.mkdir(parents=True, exist_ok=True)
                fd = os.open(lp, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as e:
                raise environment_error(e, shown) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as e:
                os.close(fd)
                if e.errno not in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                    return cls._acquire_excl(out, shown, command)  # no flock on this FS
                raise _busy(lp, shown) from None
            # the file may have been removed by its previous holder between open and flock
            try:
                same = os.stat(lp).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                _write_holder(fd, lp, shown, command)
                return cls(lp, fd)
            os.close(fd)
        raise InputError("cannot lock the output (lock file keeps changing)", file=shown)

    @classmethod
    def _acquire_excl(cls, out: Path, shown: str | Path, command: str) -> _Lock:
        lp = cls.lock_path(out)
        for _ in range(20):
            try:
                out.parent.mkdir(parents=True, exist_ok=True)
                fd = os.open(lp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                pid = _holder_pid(lp)
                if pid is None or _pid_alive(pid):
                    raise _busy(lp, shown) from None
                # stale: move it aside under a unique name (only one taker wins), then retry
                with contextlib.suppress(FileNotFoundError):
                    os.replace(lp, lp.with_name(f"{lp.name}.stale.{os.getpid()}"))
                    os.unlink(lp.with_name(f"{lp.name}.stale.{os.getpid()}"))
                continue
            except OSError as e:
                raise environment_error(e, shown) from None
            _write_holder(fd, lp, shown, command)
            return cls(lp, fd)
        raise InputError("cannot lock the output (lock file keeps changing)", file=shown)

    def release(self, remove_made: bool = False) -> None:
        if self.fd is None:
            return
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)  # unlink while still holding it: see the inode check above
        os.close(self.fd)
        self.fd = None
        if remove_made:  # nothing was written: take back the empty parents made for it
            for d in reversed(self.made):
                with contextlib.suppress(OSError):
                    d.rmdir()


def _write_holder(fd: int, lock_file: Path, shown: str | Path, command: str) -> None:
    """Write ``pid N roboisf COMMAND`` into the lock; when the disk refuses (full, quota), remove
    the lock file again and say so: no empty lock is left behind."""
    try:
        os.ftruncate(fd, 0)
        data = f"pid {os.getpid()} roboisf {command}\n".encode()
        if os.write(fd, data) != len(data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    except OSError as e:
        with contextlib.suppress(OSError):
            os.unlink(lock_file)
        os.close(fd)
        raise environment_error(e, shown) from None


def _busy(lock_file: Path, shown: str | Path) -> InputError:
    return InputError(
        f"another roboisf run is writing this output ({_holder(lock_file)}); wait for it to "
        "finish or choose another -o",
        file=shown,
    )


def _holder_pid(lock_file: Path) -> int | None:
    """The pid written in a lock file (``pid N …``); None while it is being written."""
    parts = _holder(lock_file).split()
    if len(parts) >= 2 and parts[0] == "pid" and parts[1].isdigit():
        return int(parts[1])
    return None


def _holder(lock_file: Path) -> str:
    try:
        text = lock_file.read_text(encoding="utf-8", errors="replace").strip()
    except OSError:
        return "holder unknown"
    return text[:200] or "holder unknown"


# --------------------------------------------------------------------------------------------
# staging


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _make_work_dir(out: Path, kind: str) -> Path:
    d = Path(tempfile.mkdtemp(prefix=f".{out.name}.{kind}.", dir=out.parent))
    try:
        (d / STAGING_MARKER).write_text(
            json.dumps({"format": _MARKER_FORMAT, "pid": os.getpid(), "output": out.name}),
            encoding="utf-8",
        )
    except BaseException:  # a full disk: no staging folder without its marker is left behind
        shutil.rmtree(d, ignore_errors=True)
        raise
    return d


def _clean_stale(out: Path) -> list[Path]:
    """Remove ``.NAME.staging.*``/``.NAME.old.*`` folders left by dead roboisf runs."""
    removed: list[Path] = []
    prefixes = (f".{out.name}.staging.", f".{out.name}.old.")
    try:
        entries = list(os.scandir(out.parent))
    except OSError:
        return removed
    for e in entries:
        if not e.name.startswith(prefixes) or not e.is_dir(follow_symlinks=False):
            continue
        try:
            info = json.loads(Path(e.path, STAGING_MARKER).read_text(encoding="utf-8"))
            pid = int(info["pid"])
            ours = info.get("format") == _MARKER_FORMAT and info.get("output") == out.name
        except (OSError, ValueError, KeyError, TypeError):
            continue  # not provably ours: leave it
        if ours and not _pid_alive(pid):
            with deferred_signals():
                shutil.rmtree(e.path, ignore_errors=True)
            removed.append(Path(e.path))
    return removed


def _default_mode(base: int) -> int:
    mask = os.umask(0)
    os.umask(mask)
    return base & ~mask


def _walk_files(root: Path) -> list[PurePosixPath]:
    files = []
    for dirpath, dirnames, filenames in os.walk(root):
        rel_dir = PurePosixPath(os.path.relpath(dirpath, root))
        for name in filenames + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]:
            rel = rel_dir / name if str(rel_dir) != "." else PurePosixPath(name)
            if rel == PurePosixPath(STAGING_MARKER) or rel == PurePosixPath(MARKER):
                continue
            files.append(rel)
    return files


@contextlib.contextmanager
def staged_output_dir(
    path: str | Path, command: str | None = None, *, overwrite: bool = False
) -> Iterator[Path]:
    """Build an output folder in a staging folder; move it into place when the block succeeds.

    Uses the claim of ``path`` made by the command (:func:`claim_output_dir`) or makes one
    (checks and lock) for the duration. On success the new files replace the files of the
    previous roboisf result (listed in its marker) and the marker is rewritten; files roboisf did
    not write are left exactly as they are. On an exception (including :class:`Interrupted`) the
    staging folder is removed and ``path`` is left as it was.

    Yields
    ------
    Path
        The empty staging folder to write into.
    """
    out = _resolve(path)
    claim = _active_claim(out)
    own: OutputClaim | None = None
    if claim is None:
        own = _claim_dir(out, path, command or "python", overwrite, ())
        claim = own
    stage: Path | None = None
    try:
        try:
            with deferred_signals():  # a signal right after mkdtemp still finds `stage` set
                stage = _make_work_dir(out, "staging")
            yield stage
            with deferred_signals():
                _commit(stage, out, path, claim.command)
                claim.committed = True
        except BaseException:
            if stage is not None:
                with deferred_signals():
                    shutil.rmtree(stage, ignore_errors=True)
            raise
    finally:
        if own is not None:
            own.release()


def _commit(stage: Path, out: Path, shown: str | Path, command: str) -> None:
    new_files = _walk_files(stage)
    os.unlink(stage / STAGING_MARKER)
    marker = _marker_data(command, stage, new_files)
    if not out.exists():
        with open(stage / MARKER, "w", encoding="utf-8") as fh:
            json.dump(marker, fh, indent=1)
        os.chmod(stage, _default_mode(0o777))
        os.replace(stage, out)
        return
    prev = _previous_files(out, read_marker(out))
    ours = set(prev.ours)
    # a new file may not land on (or under) anything roboisf did not write
    for rel in new_files:
        cur = out
        for i, part in enumerate(rel.parts):
            cur = cur / part
            is_last = i == len(rel.parts) - 1
            if not os.path.lexists(cur):
                break
            if is_last:
                if PurePosixPath(*rel.parts[: i + 1]) not in ours:
                    raise InputError(
                        f"{rel} exists and roboisf did not write it; nothing was written "
                        "(move that file away and run again)",
                        file=shown,
                    )
            elif not cur.is_dir() or cur.is_symlink():
                raise InputError(
                    f"{PurePosixPath(*rel.parts[: i + 1])} is in the way of {rel}; nothing "
                    "was written (move it away and run again)",
                    file=shown,
                )
    backup = _make_work_dir(out, "old")
    moved_old: list[PurePosixPath] = []
    moved_new: list[PurePosixPath] = []
    made_dirs: list[Path] = []
    old_marker = out / MARKER
    had_marker = os.path.lexists(old_marker) and read_marker(out) is not None
    try:
        for rel in prev.ours:
            (backup / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(out / rel, backup / rel)
            moved_old.append(rel)
        if had_marker:
            os.replace(old_marker, backup / MARKER)
        for rel in new_files:
            target = out / rel
            for anc in reversed(rel.parents[:-1]):
                d = out / anc
                if not d.exists():
                    d.mkdir(mode=_default_mode(0o777))
                    made_dirs.append(d)
            os.replace(stage / rel, target)
            moved_new.append(rel)
        with open(stage / MARKER, "w", encoding="utf-8") as fh:
            json.dump(marker, fh, indent=1)
        os.replace(stage / MARKER, old_marker)
    except BaseException:
        for rel in reversed(moved_new):
            with contextlib.suppress(OSError):
                os.replace(out / rel, stage / rel)
        for d in reversed(made_dirs):
            with contextlib.suppress(OSError):
                d.rmdir()
        for rel in moved_old:
            with contextlib.suppress(OSError):
                os.replace(backup / rel, out / rel)
        if had_marker:
            with contextlib.suppress(OSError):
                os.replace(backup / MARKER, old_marker)
        shutil.rmtree(backup, ignore_errors=True)
        raise
    shutil.rmtree(backup, ignore_errors=True)
    shutil.rmtree(stage, ignore_errors=True)
    # folders that only held old roboisf files and are empty now
    new_dirs = {p for rel in new_files for p in rel.parents}
    old_dirs = sorted(
        {p for rel in prev.ours for p in rel.parents if str(p) != "." and p not in new_dirs},
        key=lambda p: -len(p.parts),
    )
    for rel_dir in old_dirs:
        with contextlib.suppress(OSError):
            (out / rel_dir).rmdir()  # only if empty: a user's file inside keeps it


def final_location(path: str | Path) -> Path:
    """Where ``path`` (absolute) will be once every staging folder above it is moved into place.

    A result that names one of its own files (``analyze``'s ``identified_stiffness``) is written
    inside a staging folder — its own, or that of an enclosing command such as ``demo`` — and
    must name the file where it ends up. Each ancestor carrying a :data:`STAGING_MARKER` is
    replaced by the output it stages (its ``output`` entry, a sibling name)."""
    p = Path(path).resolve()
    real = out = Path(p.parts[0])
    for part in p.parts[1:]:
        real = real / part
        try:
            info = json.loads((real / STAGING_MARKER).read_text(encoding="utf-8"))
            name = info["output"] if isinstance(info, dict) else None
        except (OSError, ValueError, KeyError):
            name = None
        out = out / (name if isinstance(name, str) and name and "/" not in name else part)
    return out
