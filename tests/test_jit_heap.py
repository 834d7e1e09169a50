"""roboisf.jit.heap: the C heap's policy (glibc's malloc_trim and mallopt)."""

from __future__ import annotations

import os
import pathlib
import platform
import subprocess
import sys

import pytest

import roboisf
from roboisf.jit import heap

GLIBC = platform.libc_ver()[0] == "glibc"

# a computation that makes and drops the same temporaries again and again (as plan's numpy
# engine does per placement): 20 arrays of 2.5 MB made, filled and freed, 15 rounds; prints
# the minor page faults of the rounds after the first
_ROUNDS = """
import resource, sys
import numpy as np
from roboisf.jit import heap
if sys.argv[1] == "hold":
    assert heap.hold_freed_memory()
def rounds(n):
    for _ in range(n):
        arrays = [np.ones(327_680) for _ in range(20)]  # 2.5 MB each, every page written
        del arrays
rounds(1)
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
rounds(15)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> int:
    src = str(pathlib.Path(roboisf.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": src}
    for k in ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TOP_PAD_"):
        env.pop(k, None)
    res = subprocess.run(
        [sys.executable, "-c", _ROUNDS, mode], env=env, capture_output=True, text=True, timeout=60
    )
    assert res.returncode == 0, res.stderr
    return int(res.stdout.strip())


@pytest.mark.skipif(not GLIBC, reason="glibc's malloc only")
def test_held_memory_is_reused_instead_of_faulted_in_again():
    """By default glibc gives the 50 MB back after each round and faults it in again on the
    next (≈ 12 800 pages a round); held, the later rounds reuse the first round's pages."""
    default, held = _faults("default"), _faults("hold")
    pages_per_round = 20 * 327_680 * 8 // 4096
    assert default > 5 * pages_per_round  # the default policy does fault the rounds in again
    assert held < pages_per_round  # held: less than one round's pages in all 15 rounds


def test_the_heap_functions_never_raise_off_glibc(monkeypatch):
    monkeypatch.setattr(heap, "_libc", lambda: None)
    assert heap.trim() is False
    assert heap.hold_freed_memory() is False
