"""The optional numba import, its fallback, and whether numba holds a module's cache.

numba is a dependency (its kernels are built at install: :mod:`roboisf.jit.prebuild`), but a
run can do without it: ``ROBOISF_NUMBA=0``, or an install where it does not import.
:data:`HAVE_NUMBA` says whether it is there without importing it (≈ 0.5 s); :func:`njit`
makes each kernel's dispatcher on its first call (:class:`LazyKernel`), so a process pays
numba's import only when it runs a numba kernel — not when it imports a kernel module whose C
form (:mod:`roboisf.jit.native`) serves it. Without numba :func:`njit` returns the function
unchanged.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import io
import os
import pickletools
import re
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

from roboisf.progress import notice_once

__all__ = [
    "COMPILE_WAIT",
    "HAVE_NUMBA",
    "NUMBA_ENV",
    "LazyKernel",
    "compile_notice",
    "kernel_cached",
    "njit",
    "numba_module",
    "python_copy",
]


#: Environment switch: "0" runs roboisf as if numba were not installed (the numpy engines
#: throughout; inherited by the processes roboisf starts).
NUMBA_ENV = "ROBOISF_NUMBA"


def _installed() -> bool:
    if os.environ.get(NUMBA_ENV, "1").strip() == "0":
        return False
    try:
        return importlib.util.find_spec("numba") is not None
    except (ImportError, ValueError):  # pragma: no cover - a broken install
        return False


#: numba is installed (imported only when a kernel module is first imported) and not switched
#: off (:data:`NUMBA_ENV`).
HAVE_NUMBA = _installed()

#: What a build of the compiled kernels in the foreground costs, as :func:`compile_notice` says
#: it (``ROBOISF_BACKGROUND_COMPILE=0`` or an explicit ``backend="numba"``; measured:
#: docs/report.md, "The terminal").
COMPILE_WAIT = "about 30 s to 2 minutes, once (longer on a busy machine)"


def numba_module() -> ModuleType | None:
    """The numba module (imported on first call), or None when it is not installed."""
    if not HAVE_NUMBA:
        return None
    import numba

    return numba


def _identity(f: Callable[..., Any]) -> Callable[..., Any]:
    return f


_plain = 0  # > 0 while python_copy executes a module: njit is the identity
_copies: dict[str, ModuleType] = {}


def njit(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """The decorator of every roboisf kernel: ``numba.njit(cache=True, nogil=True, **options)``
    (cached on disk, releases the GIL) made on first use (:class:`LazyKernel`), or the identity
    without numba."""
    if _plain or not HAVE_NUMBA:
        return _identity
    opts = {"cache": True, "nogil": True, **options}
    return lambda f: LazyKernel(f, opts)


_materializing = threading.RLock()


class LazyKernel:
    """A numba kernel whose dispatcher — and so numba's import (≈ 0.15–0.2 s) and its first
    load (≈ 0.2 s more) — is made on its first call or attribute read, not when its module is
    imported: a process that runs a kernel's C form (:mod:`roboisf.jit.native`) or its numpy
    form never imports numba.

    On that first use every kernel named in the module's globals (the kernel's own module's,
    and those of the kernels it names, in turn) is replaced there by its dispatcher, so the
    kernels a compiled kernel calls are numba's own objects when numba types it. Pickled by
    reference to its module and name, as a function is."""

    def __init__(self, func: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = func
        self._options = options
        self._dispatcher: Any = None
        functools.update_wrapper(self, func)

    def dispatcher(self) -> Any:
        """numba's dispatcher of this kernel (made, and the globals bound, on first call)."""
        d = self._dispatcher
        if d is not None:
            return d
        with _materializing:
            if self._dispatcher is None:
                _notice(self.py_func.__code__.co_filename)
                nb = numba_module()
                assert nb is not None  # LazyKernel is made only with numba installed
                self._dispatcher = nb.njit(**self._options)(self.py_func)
                _bind(self.py_func.__globals__, set())
            return self._dispatcher

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.dispatcher()(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name in ("py_func", "_options", "_dispatcher"):
            raise AttributeError(name)
        return getattr(self.dispatcher(), name)

    def __reduce__(self) -> tuple[Any, tuple[str, str]]:
        return (_by_name, (self.py_func.__module__, self.py_func.__qualname__))

    def __repr__(self) -> str:
        return f"<roboisf kernel {self.py_func.__module__}.{self.py_func.__qualname__}>"


def _bind(namespace: dict[str, Any], seen: set[int]) -> None:
    """Replace every :class:`LazyKernel` in ``namespace`` (a module's globals) by its
    dispatcher, and do the same in the globals of each (once per namespace)."""
    if id(namespace) in seen:
        return
    seen.add(id(namespace))
    for name, value in list(namespace.items()):
        if isinstance(value, LazyKernel):
            namespace[name] = value.dispatcher()
            _bind(value.py_func.__globals__, seen)


def _by_name(module: str, qualname: str) -> Any:
    import importlib

    obj: Any = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def python_copy(module_name: str) -> ModuleType:
    """A private second copy of the kernel module ``module_name`` whose kernels are plain Python
    (:func:`njit` is the identity while it executes; cached per process).

    For a kernel that calls kernels of another module and runs as Python on a cold kernel cache
    (:func:`roboisf.jit.ready` False): calling the other module's numba functions from Python
    would compile them, the wait the cold path is there to avoid. The module itself (and so
    every compiled caller of it) is untouched.
    """
    global _plain
    if module_name not in _copies:
        spec = importlib.util.find_spec(module_name)
        if spec is None or spec.origin is None:
            raise ImportError(f"no module {module_name!r}")
        copy = importlib.util.spec_from_file_location(f"{module_name}__python", spec.origin)
        assert copy is not None and copy.loader is not None
        module = importlib.util.module_from_spec(copy)
        _plain += 1
        try:
            copy.loader.exec_module(module)
        finally:
            _plain -= 1
        _copies[module_name] = module
    return _copies[module_name]


def _cache_dirs(source: Path) -> list[Path]:
    """Where numba keeps — and looks for — the on-disk cache of ``source``'s ``cache=True``
    functions, as its locators choose (``numba.core.caching``, first that applies):
    ``$NUMBA_CACHE_DIR``; else ``__pycache__`` beside the source **when numba can write
    there**; else the user's cache folder. Outside ``__pycache__`` the folder is named after the
    source's folder and the SHA-1 of its absolute path (``get_suitable_cache_subpath``).

    Only the one folder numba uses: an install made by another user (a system-wide or container
    install run unprivileged) has a read-only ``__pycache__`` holding the kernels built at
    install, which numba then ignores — it compiles into the user's folder. Counting that
    cache as ready made such a run compile in the foreground."""
    parent = os.path.dirname(os.path.abspath(source))
    sub = os.path.basename(parent) + "_" + hashlib.sha1(parent.encode()).hexdigest()
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:  # numba then looks nowhere else
        return [Path(env) / sub]
    pycache = source.parent / "__pycache__"
    if _writable_folder(pycache):
        return [pycache]
    return [_user_cache_root() / sub]


def _writable_folder(folder: Path) -> bool:
    """Whether numba's in-tree locator takes ``folder``: it exists and is writable, or can be
    made (numba creates it and writes a temporary file there to check)."""
    probe = folder
    while not probe.exists():
        if probe.parent == probe:
            return False
        probe = probe.parent
    return probe.is_dir() and os.access(probe, os.W_OK | os.X_OK)


def _user_cache_root() -> Path:
    """numba's user-wide cache folder (``appdirs.user_cache_dir("numba")``): on Linux
    ``$XDG_CACHE_HOME/numba`` (default ``~/.cache/numba``), on macOS
    ``~/Library/Caches/numba``, on Windows ``%LOCALAPPDATA%\\numba\\Cache``."""
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "numba"
    if sys.platform.startswith("win"):
        local = os.environ.get("LOCALAPPDATA") or str(Path.home() / "AppData" / "Local")
        return Path(local) / "numba" / "Cache"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "numba"


def kernel_cached(module_file: str | os.PathLike[str], *, dirs: list[Path] | None = None) -> bool:
    """True when numba holds a cache index of the module's kernels that numba itself will take
    as fresh (else its first call compiles them). Reads the head of each index file, and the
    source when its content is the key; ``dirs``: the cache folders to look in (default:
    numba's, :func:`_cache_dirs`).

    An index that is fresh by version and source must also hold code for *this* CPU
    (:func:`_host_cpu`: its name and features, numba's key of an entry): a cache built on
    another machine — a wheel built at install and carried to the cell's PC, a home folder
    shared by machines of several CPUs — would otherwise be taken as ready and numba would
    compile in the foreground. Only that last check imports numba (≈ 0.3 s, which the
    compiled run it allows pays anyway).

    Fresh is judged as numba judges it (:func:`_index_fresh`): the index's numba version is the
    installed one, and its source stamp is the source's — a SHA-256 of the source's bytes in
    numba ≥ 0.61, (mtime, size) before. Comparing file times instead (what this did until
    2026-11) was wrong both ways: a source whose mtime changed but not its content (a checkout
    and back, a reinstall, a copy) kept its cache in numba's eyes but looked stale here — every
    run took the numpy path and started a builder that then "left no cache" (numba had nothing
    to write) and marked the build failed. An index of unknown format falls back to the times.
    """
    source = Path(module_file)
    try:
        st = source.stat()
    except OSError:
        return True  # nothing to compare: say nothing
    for folder in _cache_dirs(source) if dirs is None else dirs:
        try:
            indexes = list(folder.glob(f"{source.stem}.*.nbi"))
        except OSError:
            continue
        for index in indexes:
            fresh = _index_fresh(index, source, st)
            if fresh is None:  # an index format this does not know: its time against the source's
                try:
                    fresh = index.stat().st_mtime >= st.st_mtime
                except OSError:
                    fresh = False
            elif fresh:
                fresh = _for_this_cpu(index)
            if fresh:
                return True
    return False


@functools.cache
def _host_cpu() -> tuple[bytes, bytes] | None:
    """This machine's CPU as numba keys its cache entries — its name and feature string
    (``codegen.magic_tuple()``, with numba's own ``NUMBA_CPU_NAME`` / ``NUMBA_CPU_FEATURES`` /
    ``NUMBA_ENABLE_AVX`` settings applied) — UTF-8 encoded as pickle stores them; None when
    numba cannot say (then no entry is rejected for its CPU)."""
    try:
        import llvmlite.binding as ll
        from numba.core import config
        from numba.core.codegen import get_host_cpu_features

        cpu_name = getattr(config, "CPU_NAME", None)  # set from the environment at import
        cpu_features = getattr(config, "CPU_FEATURES", None)
        name = cpu_name or ll.get_host_cpu_name()
        features = cpu_features if cpu_features is not None else get_host_cpu_features()
    except Exception:  # pragma: no cover - numba missing or broken: numba will say so itself
        return None
    return str(name).encode(), str(features).encode()


def _for_this_cpu(index: Path) -> bool:
    """Whether the cache index ``index`` holds an entry compiled for this CPU: its name and its
    feature string both appear in the index (they are the two strings of each entry's key
    after the target triple; an index is a few kB)."""
    cpu = _host_cpu()
    if cpu is None:
        return True
    try:
        data = index.read_bytes()
    except OSError:
        return False
    return cpu[0] in data and cpu[1] in data


@functools.cache
def numba_version_installed() -> str | None:
    """The installed numba's version without importing it, None if unknown: numba's own
    ``numba/_version.py`` (versioneer's JSON; ~0.1 ms, where the package metadata took 30 ms
    of every command's start), else the metadata."""
    mod = sys.modules.get("numba")
    if mod is not None:
        return str(getattr(mod, "__version__", "")) or None
    try:
        spec = importlib.util.find_spec("numba")
        if spec is not None and spec.origin:
            text = Path(spec.origin).with_name("_version.py").read_text(encoding="utf-8")
            found = re.search(r'"version":\s*"([^"]+)"', text)
            if found:
                return found.group(1)
    except (OSError, ValueError, ImportError):
        found = None  # unreadable: numba's metadata below
    try:
        from importlib.metadata import version

        return version("numba")
    except Exception:  # pragma: no cover - metadata missing
        return None


@functools.cache
def _source_sha256(path: str, mtime_ns: int, size: int) -> bytes:
    """SHA-256 of a source's bytes (numba's stamp since 0.61), per (path, mtime, size)."""
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).digest()


#: pickle opcodes of a bytes value / of an int value
_BYTES_OPS = ("SHORT_BINBYTES", "BINBYTES", "BINBYTES8")
_INT_OPS = ("BININT", "BININT1", "BININT2", "LONG1", "LONG4", "INT", "LONG")


def _index_fresh(index: Path, source: Path, st: os.stat_result) -> bool | None:
    """Whether numba takes the cache index ``index`` as fresh for ``source`` (stat ``st``); None
    when its format is not the one this reads.

    numba writes an index as two pickles: its version string, then ``(stamp, overloads)``
    (``numba.core.caching.IndexDataCacheFile``). Only the opcodes up to the stamp are read
    (:func:`pickletools.genops` parses without executing; the overloads' numba types would
    import numba): the version must be the installed numba's, and the stamp the SHA-256 of the
    source's bytes (numba ≥ 0.61) or its (mtime, size) (numba < 0.61)."""
    try:
        with open(index, "rb") as f:
            head = f.read(512)
    except OSError:
        return False
    try:
        stream = io.BytesIO(head)
        version = None
        for op, arg, _ in pickletools.genops(stream):
            if op.name in ("SHORT_BINUNICODE", "BINUNICODE", "BINUNICODE8"):
                version = arg
            if op.name == "STOP":
                break
        values: list[Any] = []
        for op, arg, _ in pickletools.genops(stream):
            if op.name in ("PROTO", "FRAME", "MEMOIZE", "MARK"):
                continue
            if op.name in _BYTES_OPS or op.name == "BINFLOAT" or op.name in _INT_OPS:
                values.append(arg)
                if isinstance(arg, bytes) or len(values) == 2:
                    break
                continue
            return None
    except (ValueError, EOFError):  # not a pickle this can read (or a truncated head)
        return None
    if not isinstance(version, str) or not values:
        return None
    installed = numba_version_installed()
    if installed is not None and version != installed:
        return False  # numba ignores an index of another version: it would compile
    if isinstance(values[0], bytes):
        return values[0] == _source_sha256(str(source), st.st_mtime_ns, st.st_size)
    if len(values) == 2 and isinstance(values[0], float) and isinstance(values[1], int):
        return values[0] == st.st_mtime and values[1] == st.st_size
    return None


def compile_notice(module_file: str | os.PathLike[str]) -> None:
    """Called by a kernel module as it is imported (its numba functions compile on first call):
    the module's notice is said, if it is due, when its first numba kernel is about to be made
    (:class:`LazyKernel`) — not at the import, which may be followed by the module's C form
    only (:mod:`roboisf.jit.native`) and no numba at all (checking numba's cache here imported
    numba)."""
    _notice_due.add(os.path.abspath(module_file))


_notice_due: set[str] = set()


def _notice(module_file: str) -> None:
    """The notice of :func:`compile_notice` for ``module_file``, at most once: when its kernels
    are not cached yet and they would compile here — background building off
    (``ROBOISF_BACKGROUND_COMPILE=0``) — say once per process that the kernels are being built
    and how long that takes (:data:`COMPILE_WAIT`), through :func:`roboisf.progress.set_notice`'s
    hook, silent without one. With background building on, nothing compiles unasked: the
    dispatch (:func:`roboisf.jit.ready`) runs numpy and says so when it starts the builder;
    said here, the notice claimed a wait that did not come and, being the run's one notice,
    kept the builder's from being said. (An explicit ``backend="numba"`` on an uncached kernel
    then compiles without a notice.)"""
    path = os.path.abspath(module_file)
    if path not in _notice_due:
        return
    _notice_due.discard(path)
    from roboisf.jit.background import background_enabled

    if background_enabled() or kernel_cached(path):
        return
    notice_once(
        "building roboisf's compiled kernels (numba) for the first time — "
        f"{COMPILE_WAIT}; they are cached on disk, later runs start in seconds"
    )
