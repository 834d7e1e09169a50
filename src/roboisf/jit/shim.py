"""The optional numba import, its fallback, and whether numba holds a module's cache.

numba is an extra (``pip install 'roboisf[fast]'``). :data:`HAVE_NUMBA` says whether it is
installed without importing it (≈ 0.5 s); :func:`njit` imports it on first use, so a kernel
module pays the import only when it is itself imported. Without numba :func:`njit` returns the
function unchanged and :func:`prange` gives :func:`range`.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

from roboisf.progress import notice_once

__all__ = [
    "COMPILE_WAIT",
    "HAVE_NUMBA",
    "NUMBA_ENV",
    "compile_notice",
    "kernel_cached",
    "njit",
    "numba_module",
    "prange",
    "python_copy",
]


#: Environment switch: "0" runs roboisf as if numba were not installed (the numpy engines
#: throughout, as the plain install does; inherited by the processes roboisf starts).
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
    (cached on disk, releases the GIL), or the identity without numba."""
    nb = None if _plain else numba_module()
    if nb is None:
        return _identity
    return nb.njit(**{"cache": True, "nogil": True, **options})


def prange() -> Any:
    """``numba.prange`` (imports numba), or :func:`range` without numba: bind it at module level
    (``_PRANGE = prange()``) and loop ``for i in _PRANGE(n)`` in a ``parallel=True`` kernel."""
    nb = numba_module()
    return range if nb is None else nb.prange


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
    """Where numba keeps the on-disk cache of ``source``'s ``cache=True`` functions: beside it
    in ``__pycache__``, or under ``$NUMBA_CACHE_DIR`` / the user's cache folder in a folder
    named after the source's folder and the SHA-1 of its absolute path (numba's
    ``_CacheLocator.get_suitable_cache_subpath``)."""
    parent = os.path.dirname(os.path.abspath(source))
    sub = os.path.basename(parent) + "_" + hashlib.sha1(parent.encode()).hexdigest()
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:  # numba then looks nowhere else
        return [Path(env) / sub]
    return [source.parent / "__pycache__", Path.home() / ".cache" / "numba" / sub]


def kernel_cached(module_file: str | os.PathLike[str]) -> bool:
    """True when numba holds a cache index of the module's kernels at least as new as the module
    (else its first call compiles them). Reads file names and times only; imports nothing."""
    source = Path(module_file)
    try:
        stamp = source.stat().st_mtime
    except OSError:
        return True  # nothing to compare: say nothing
    for folder in _cache_dirs(source):
        try:
            for index in folder.glob(f"{source.stem}.*.nbi"):
                if index.stat().st_mtime >= stamp:
                    return True
        except OSError:
            continue
    return False


def compile_notice(module_file: str | os.PathLike[str]) -> None:
    """Called by a kernel module as it is imported (its numba functions compile on first call):
    when they are not cached yet, say once per process that the kernels are being built and how
    long that takes (:data:`COMPILE_WAIT`) — through :func:`roboisf.progress.set_notice`'s hook,
    silent without one."""
    if kernel_cached(module_file):
        return
    notice_once(
        "building roboisf's compiled kernels (numba) for the first time — "
        f"{COMPILE_WAIT}; they are cached on disk, later runs start in seconds"
    )
