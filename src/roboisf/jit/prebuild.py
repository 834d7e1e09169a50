"""The compiled kernels built at install: ``python -m roboisf.jit.prebuild ROOT``.

``pip install`` runs this (``setup.py``'s ``build_kernels`` step, in the build environment,
which has numba) on the package it is about to install: ``ROOT`` is the folder holding the
``roboisf`` package being built — the build's ``build/lib`` for a wheel, ``src`` for an
editable install. The kernel groups (:data:`roboisf.jit.GROUPS`) whose C forms were not built
(no C compiler, :mod:`roboisf.jit.native`) are compiled with numba
(:func:`roboisf.jit.background.build_missing`), and numba writes its cache *beside the sources*
(``__pycache__``, numba's in-tree cache), so the installed package carries it: the first
command after the install runs compiled, with no minute of compiling and no background builder.
Where every C form is built, nothing is compiled with numba (28–30 CPU-s of a wheel's 38 on the
machine of docs/speed.md): the C forms serve every call, and numba would serve only
``ROBOISF_NATIVE=0`` or a C library refused at run time — then the background builder builds it,
numpy serving meanwhile. ``--all`` builds every group anyway: the editable install of a checkout
does (its tests run both forms side by side, and an edited ``.c`` file is refused until rebuilt).

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


def in_tree_missing(root: Path, *, skip_native: bool = False) -> list[str]:
    """The kernel groups whose modules under ``root`` have no fresh in-tree numba cache
    (``__pycache__`` beside each source), by name; ``skip_native``: not those the C forms serve
    (:func:`roboisf.jit.background.native_ready`, in this process)."""
    from roboisf.jit.background import GROUPS, native_ready
    from roboisf.jit.shim import kernel_cached

    missing = []
    for name, group in GROUPS.items():
        if skip_native and native_ready(name):
            continue
        files = [root.joinpath(*m.split(".")).with_suffix(".py") for m in group.modules]
        if not all(kernel_cached(f, dirs=[f.parent / "__pycache__"]) for f in files):
            missing.append(name)
    return missing


def _not_from(root: Path) -> str:
    """Why this process's ``roboisf`` is not the package under ``root`` ("" when it is): the
    C forms and the caches it finds must be that package's."""
    import roboisf

    here = Path(roboisf.__file__).resolve().parent
    return (
        ""
        if here == (root / "roboisf").resolve()
        else f"roboisf was imported from {here}, not from {root}"
    )


def build_into(root: Path, *, every_group: bool = False) -> list[str]:
    """Build the kernel groups of the ``roboisf`` package under ``root`` that its C forms do
    not serve (``every_group``: all of them) into their in-tree cache; the problems, one line
    each (empty: all built and found beside the sources).

    Must run in a process that imported ``roboisf`` from ``root`` and has no
    ``NUMBA_CACHE_DIR`` (numba would write there instead): :func:`main` checks both."""
    from roboisf.jit.background import build_missing

    wrong = _not_from(root)
    if wrong:
        return [wrong]
    failures = build_missing(skip_native=not every_group)
    missing = in_tree_missing(root, skip_native=not every_group)
    if missing and not failures:
        failures = [
            f"{', '.join(missing)}: built, but numba left no cache beside the sources (is "
            f"{root} writable?)"
        ]
    return failures


def main(argv: list[str]) -> int:
    """``ROOT [--all]``: build into the package under ``ROOT`` (``--all``: every group, also
    those its C forms serve); prints one line per outcome; 0 when every group asked for is built
    (or none needs numba, or the step is skipped), 1 when not."""
    every_group = "--all" in argv
    args = [a for a in argv if a != "--all"]
    if len(args) != 1:
        print("usage: python -m roboisf.jit.prebuild ROOT [--all]", file=sys.stderr)
        return 2
    root = Path(args[0]).resolve()
    if os.environ.get(SKIP_ENV, "1").strip() == "0":
        print(f"roboisf kernels: not built ({SKIP_ENV}=0)")
        return 0
    if os.environ.get("NUMBA_CACHE_DIR"):
        print("roboisf kernels: not built (NUMBA_CACHE_DIR is set: numba would cache there)")
        return 1
    if not every_group and not _not_from(root):
        from roboisf.jit.background import GROUPS, native_ready

        if all(native_ready(g) for g in GROUPS):
            print(
                "roboisf kernels: the C kernels serve every group; no numba kernel built "
                "(numba is their fallback, built in the background if ever needed)"
            )
            return 0
    from roboisf.jit.shim import HAVE_NUMBA

    if not HAVE_NUMBA:
        print("roboisf kernels: not built (numba is not importable here, or ROBOISF_NUMBA=0)")
        return 1
    from roboisf.jit.background import ENV

    # the kernels are compiled here, in the foreground, never handed to a background builder
    # (setup.py sets this too; run by hand without it, the kernels whose callers ask
    # jit.ready — the online loop's, the position alignment's — took their numpy path and
    # numba compiled nothing for them)
    os.environ[ENV] = "0"
    t = time.perf_counter()
    failures = build_into(root, every_group=every_group)
    if failures:
        print("roboisf kernels: not all built; the background builder will finish them:")
        for line in failures:
            print(f"  {line}")
        return 1
    print(f"roboisf kernels: built in {time.perf_counter() - t:.1f} s (numba cache beside them)")
    return 0


if __name__ == "__main__":  # pragma: no cover - run by setup.py's build_kernels
    raise SystemExit(main(sys.argv[1:]))
