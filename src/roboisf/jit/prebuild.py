"""The compiled kernels built at install: ``python -m roboisf.jit.prebuild ROOT``.

``pip install`` runs this (``setup.py``'s ``build_kernels`` step, in the build environment,
which has numba) on the package it is about to install: ``ROOT`` is the folder holding the
``roboisf`` package being built — the build's ``build/lib`` for a wheel, ``src`` for an
editable install. Every kernel group (:data:`roboisf.jit.GROUPS`) is compiled with
:func:`roboisf.jit.background.build_missing`, and numba writes its cache *beside the sources*
(``__pycache__``, numba's in-tree cache), so the installed package carries it: the first
command after the install runs compiled, with no minute of compiling and no background builder.

numba takes such a cache as its own when (numba ≥ 0.61) the source's bytes are the ones it was
built from (a SHA-256, not the file's time, so the copy into site-packages keeps it), the numba
version is the same, and the CPU is the same (its name and features are in each index entry:
:func:`roboisf.jit.shim.kernel_cached` checks them, so a wheel carried to another machine falls
back to the background builder instead of compiling in the foreground).

Never fatal: any failure prints why and the install goes on without the cache (the background
builder then serves, as before). ``ROBOISF_BUILD_KERNELS=0`` in the install's environment skips
the step.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

__all__ = ["SKIP_ENV", "build_into", "in_tree_missing", "main"]

#: Environment switch of the install: "0" skips building the kernels.
SKIP_ENV = "ROBOISF_BUILD_KERNELS"


def in_tree_missing(root: Path) -> list[str]:
    """The kernel groups whose modules under ``root`` have no fresh in-tree numba cache
    (``__pycache__`` beside each source), by name."""
    from roboisf.jit.background import GROUPS
    from roboisf.jit.shim import kernel_cached

    missing = []
    for name, group in GROUPS.items():
        files = [root.joinpath(*m.split(".")).with_suffix(".py") for m in group.modules]
        if not all(kernel_cached(f, dirs=[f.parent / "__pycache__"]) for f in files):
            missing.append(name)
    return missing


def build_into(root: Path) -> list[str]:
    """Build every kernel group of the ``roboisf`` package under ``root`` into its in-tree
    cache; the problems, one line each (empty: all built and found beside the sources).

    Must run in a process that imported ``roboisf`` from ``root`` and has no
    ``NUMBA_CACHE_DIR`` (numba would write there instead): :func:`main` checks both."""
    import roboisf
    from roboisf.jit.background import build_missing

    here = Path(roboisf.__file__).resolve().parent
    if here != (root / "roboisf").resolve():
        return [f"roboisf was imported from {here}, not from {root}"]
    failures = build_missing()
    missing = in_tree_missing(root)
    if missing and not failures:
        failures = [
            f"{', '.join(missing)}: built, but numba left no cache beside the sources (is "
            f"{root} writable?)"
        ]
    return failures


def main(argv: list[str]) -> int:
    """``ROOT``: build into the package under ``ROOT``; prints one line per outcome; 0 when
    every group is built (or the step is skipped), 1 when not."""
    if len(argv) != 1:
        print("usage: python -m roboisf.jit.prebuild ROOT", file=sys.stderr)
        return 2
    root = Path(argv[0]).resolve()
    if os.environ.get(SKIP_ENV, "1").strip() == "0":
        print(f"roboisf kernels: not built ({SKIP_ENV}=0)")
        return 0
    if os.environ.get("NUMBA_CACHE_DIR"):
        print("roboisf kernels: not built (NUMBA_CACHE_DIR is set: numba would cache there)")
        return 1
    from roboisf.jit.shim import HAVE_NUMBA

    if not HAVE_NUMBA:
        print("roboisf kernels: not built (numba is not importable here, or ROBOISF_NUMBA=0)")
        return 1
    t = time.perf_counter()
    failures = build_into(root)
    if failures:
        print("roboisf kernels: not all built; the background builder will finish them:")
        for line in failures:
            print(f"  {line}")
        return 1
    print(f"roboisf kernels: built in {time.perf_counter() - t:.1f} s (numba cache beside them)")
    return 0


if __name__ == "__main__":  # pragma: no cover - run by setup.py's build_kernels
    raise SystemExit(main(sys.argv[1:]))
