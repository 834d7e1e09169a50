"""The C heap's policy for roboisf's array work (glibc's ``malloc``; a no-op elsewhere).

numpy takes every array's memory from the C heap. glibc gives freed memory back to the system
eagerly — an array above its (adaptive) mmap threshold is unmapped on free, and a heap whose
free top passes the trim threshold is cut — so code that makes and drops the same temporaries
over and over touches fresh pages each time; on this project's 2-core VM a fresh page costs
0.8–1.8 ms per MB (docs/analyze.md). Two uses here:

* :func:`trim` — give the freed pages back once, after a large step (the analysis after its
  logs and after each scan), so that they do not sit under the next step's peak;
* :func:`hold_freed_memory` — the opposite, for a command that repeats one computation many
  times (``roboisf plan``: an IK and VJM pass over the whole toolpath per placement, a few
  hundred 0.3–3 MB temporaries each): freed memory stays in the heap for the next placement.
  On the cone's default grid (175 placements, 34 825 points) it took the numpy engine (a new
  install's first ``plan``) from 0.92 M to 0.05 M page faults and 9.0 → 7.6 s, the compiled
  one 4.4 → 4.2–4.4 s, for a peak RSS 0.23 → 0.27 GB (2 vCPUs, 2026-11-28).
"""

from __future__ import annotations

import ctypes
import functools
from typing import Any

__all__ = ["hold_freed_memory", "trim"]

#: mallopt parameters (glibc's malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3

#: arrays up to this size [bytes] come from the heap (glibc's largest allowed: 32 MiB)
HOLD_MMAP_THRESHOLD = 32 * 1024 * 1024
#: the heap keeps up to this much freed memory at its top [bytes]
HOLD_TRIM_THRESHOLD = 512 * 1024 * 1024


@functools.cache
def _libc() -> Any:
    try:
        lib = ctypes.CDLL("libc.so.6")
        lib.malloc_trim  # noqa: B018 - glibc only: AttributeError elsewhere
        lib.mallopt  # noqa: B018
        return lib
    except (OSError, AttributeError):
        return None


def trim() -> bool:
    """Give the heap's freed pages back to the system (``malloc_trim(0)``); False where there
    is no glibc."""
    lib = _libc()
    if lib is None:
        return False
    lib.malloc_trim(0)
    return True


def hold_freed_memory() -> bool:
    """For the rest of this process, keep freed memory for reuse: arrays up to
    :data:`HOLD_MMAP_THRESHOLD` from the heap, its top trimmed only beyond
    :data:`HOLD_TRIM_THRESHOLD` (glibc's ``mallopt``; this also ends its adaptive thresholds).
    Process-wide and not undone: for a command's own process (``roboisf plan``), not a library
    call. False where there is no glibc or a setting was refused."""
    lib = _libc()
    if lib is None:
        return False
    ok = lib.mallopt(_M_MMAP_THRESHOLD, HOLD_MMAP_THRESHOLD) == 1
    return bool(lib.mallopt(_M_TRIM_THRESHOLD, HOLD_TRIM_THRESHOLD) == 1 and ok)
