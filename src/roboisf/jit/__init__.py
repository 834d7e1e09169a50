"""Compiled kernels and their build: the one place roboisf touches numba.

* :func:`njit`, :data:`HAVE_NUMBA`, :func:`numba_module` — the optional numba
  import with its fallback (:mod:`roboisf.jit.shim`): a kernel module decorates with
  ``@njit()`` and runs as plain Python (or is not used) without numba.
* :func:`run_chunks`, :func:`cores` — a kernel's rows on every core from Python threads
  (:mod:`roboisf.jit.threads`; the kernels release the GIL).
* :func:`check_backend` — a ``backend=`` argument checked ("auto", "numba", "numpy").
* :func:`ready` — what every ``"auto"`` dispatch asks before running compiled: on an empty
  kernel cache the numpy path serves this run while **one** detached process builds every
  missing kernel group in the background (:mod:`roboisf.jit.background`, :data:`GROUPS`).
* :func:`kernel_cached`, :func:`compile_notice` — whether numba holds a module's cache, and the
  one-line notice of a build in the foreground.
* :mod:`roboisf.jit.native` — the C forms of the kernels (built at install, loaded with
  ctypes; a kernel module's ``_c()`` asks for its library): where they are built, no numba.

Importing this package does not import numba.
"""

from __future__ import annotations

from roboisf.jit.background import (
    BACKENDS,
    BUILD_WAIT,
    ENV,
    GROUPS,
    Group,
    background_enabled,
    check_backend,
    failure_path,
    group_cached,
    lock_path,
    ready,
)
from roboisf.jit.shim import (
    COMPILE_WAIT,
    HAVE_NUMBA,
    NUMBA_ENV,
    compile_notice,
    kernel_cached,
    njit,
    numba_module,
    python_copy,
)
from roboisf.jit.threads import cores, run_chunks

__all__ = [
    "BACKENDS",
    "BUILD_WAIT",
    "COMPILE_WAIT",
    "ENV",
    "GROUPS",
    "HAVE_NUMBA",
    "NUMBA_ENV",
    "Group",
    "background_enabled",
    "check_backend",
    "compile_notice",
    "cores",
    "failure_path",
    "group_cached",
    "kernel_cached",
    "lock_path",
    "njit",
    "numba_module",
    "python_copy",
    "ready",
    "run_chunks",
]
