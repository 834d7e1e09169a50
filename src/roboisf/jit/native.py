"""Kernels compiled ahead of time from C, built at install, loaded with :mod:`ctypes`.

Why: a numba kernel, even cached, costs every process numba's import, its typing and
lowering registries and LLVM (≈ 0.4–0.5 s of CPU under the interpreter lock and ≈ 0.12 GB
resident on the machine of docs/speed.md) before its first call. The analysis' kernels
(the scan's grid searches, the closest points on a part, the logs' passes, the position
alignment) exist also as C, one source beside each kernel module (``knn_kernel.c`` beside
``knn_kernel.py``), compiled by ``pip install`` into a small extension of its own
(``_knn_kernel_c.cpython-311-x86_64-linux-gnu.so``) and called through :mod:`ctypes`, which
releases the interpreter lock for the call as numba's ``nogil`` kernels do.

The C form is the numba form's arithmetic in its order (no fast-math, no contraction into fused
multiply-adds: :data:`CFLAGS`), so the same bits; each module's tests check it against the numba
and numpy forms. Where it is there and fresh, :func:`library` returns it and the kernel module's
Python calls it; else (``ROBOISF_NATIVE=0``, no C compiler at install, a source edited since the
build) the numba form serves as before.

Fresh: each library embeds the SHA-256 of the source it was built from
(``roboisf_source_sha256()``); a library whose source has changed since is not used (numba's
own rule for its cache). Only the standard library is imported here: ``setup.py`` loads this
file on its own for :data:`CFLAGS` and :func:`extensions`.
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import importlib.machinery
import os
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = [
    "CFLAGS",
    "ENV",
    "SANITIZE",
    "build_inplace",
    "describe",
    "extension_name",
    "extensions",
    "library",
    "reset",
    "source_sha256",
    "status",
    "suspended",
]

#: Environment switch: "0" never loads a C kernel (the numba or numpy forms serve).
ENV = "ROBOISF_NATIVE"

#: Compiler flags of every C kernel: optimised, but IEEE arithmetic as written — no fused
#: multiply-add contraction (numba's LLVM does not contract either), no fast-math; errno is
#: not set by ``sqrt`` (the result is the same correctly rounded square root).
CFLAGS = ["-O3", "-std=c11", "-ffp-contract=off", "-fno-math-errno", "-fno-strict-aliasing"]

#: The package's folder (``src/roboisf`` in a checkout).
_PACKAGE = Path(__file__).resolve().parent.parent

_loaded: dict[str, Any] = {}
_lock = threading.Lock()


def extension_name(source: Path, package: Path = _PACKAGE) -> str:
    """The extension module built from C source ``source`` (under ``package``):
    ``roboisf/scan/knn_kernel.c`` → ``roboisf.scan._knn_kernel_c``."""
    rel = source.resolve().relative_to(package.resolve().parent).with_suffix("")
    return ".".join([*rel.parts[:-1], f"_{rel.name}_c"])


def source_sha256(source: Path) -> str:
    """Hex SHA-256 of a C source's bytes, as the build embeds it."""
    return hashlib.sha256(source.read_bytes()).hexdigest()


def extensions(package: Path = _PACKAGE) -> list[tuple[str, Path, str]]:
    """Every C kernel of the package: (extension module name, source, its SHA-256)."""
    return [
        (extension_name(c, package), c, source_sha256(c))
        for c in sorted(package.rglob("*_kernel.c"))
    ]


def _switched_off() -> bool:
    return os.environ.get(ENV, "1").strip() == "0"


def _find(source: Path) -> Path | None:
    stem = f"_{source.stem}_c"
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        p = source.with_name(stem + suffix)
        if p.is_file():
            return p
    return None


#: A C function's ctypes signature: (restype, argtypes).
Signature = tuple[Any, list[Any]]


def library(kernel_module: str, signatures: dict[str, Signature] | None = None) -> Any:
    """The C library of kernel module ``kernel_module`` (dotted name; its source
    ``<module>.c`` beside it), loaded once per process, its functions typed by
    ``signatures`` (name → (restype, argtypes), applied at the load); None when there is none,
    it is stale (built from another source), it lacks a function of ``signatures``, it does
    not load, or :data:`ENV` is "0"."""
    if _suspended:
        return None
    lib = _loaded.get(kernel_module, False)
    if lib is not False:
        return lib
    with _lock:
        if kernel_module not in _loaded:
            _loaded[kernel_module] = _load(kernel_module, signatures or {})
        return _loaded[kernel_module]


def _load(kernel_module: str, signatures: dict[str, Signature]) -> Any:
    if _switched_off():
        return None
    rel = kernel_module.split(".")
    if rel[0] != _PACKAGE.name:
        return None
    source = _PACKAGE.joinpath(*rel[1:]).with_suffix(".c")
    built = _find(source)
    if built is None:
        return None
    try:
        lib = ctypes.CDLL(str(built))
        sha = ctypes.c_char_p.in_dll(lib, "roboisf_source_sha256").value
    except (OSError, ValueError, AttributeError):
        return None
    try:
        if sha is None or sha.decode() != source_sha256(source):
            return None  # built from another version of the source
    except OSError:
        pass  # the source is not installed: the library is what was shipped
    try:
        for name, (restype, argtypes) in signatures.items():
            f = getattr(lib, name)
            f.restype = restype
            f.argtypes = argtypes
    except AttributeError:
        return None  # a library without a function its module calls: not this version
    return lib


_suspended = 0


@contextlib.contextmanager
def suspended() -> Iterator[None]:
    """Within (in every thread of the process): no C form is used — :func:`library` returns
    None — so the numba kernels run; what the numba builds (:func:`roboisf.jit.background.
    build_groups`) need, since they compile by calling the modules' Python functions."""
    global _suspended
    with _lock:
        _suspended += 1
    try:
        yield
    finally:
        with _lock:
            _suspended -= 1


def status(package: Path = _PACKAGE) -> dict[str, str]:
    """Each C kernel's state, by kernel module (dotted name): "built" (its library is there and
    was built from its source), "stale" (built from another version of the source), "missing"
    (not built: no C compiler at install?), or "off" (:data:`ENV` is "0"). Loads each library
    once to read its SHA-256; numpy is not imported (``roboisf --version`` says it)."""
    out = {}
    for name, source, sha in extensions(package):
        module = name.rsplit(".", 1)[0] + "." + source.stem
        built = _find(source)
        if _switched_off():
            out[module] = "off"
        elif built is None:
            out[module] = "missing"
        else:
            try:
                got = ctypes.c_char_p.in_dll(ctypes.CDLL(str(built)), "roboisf_source_sha256")
                ok = got.value is not None and got.value.decode() == sha
            except (OSError, ValueError):
                ok = False
            out[module] = "built" if ok else "stale"
    return out


def describe(package: Path = _PACKAGE) -> str:
    """One line on the C kernels for a person: how many are built, and what to do if not."""
    states = status(package)
    n = len(states)
    built = sum(v == "built" for v in states.values())
    if n and all(v == "off" for v in states.values()):
        return f"C kernels: switched off ({ENV}=0)"
    line = f"C kernels: {built} of {n} built"
    stale = sum(v == "stale" for v in states.values())
    missing = n - built - stale
    if stale:
        line += f", {stale} stale (their sources edited: python -m roboisf.jit.native rebuilds)"
    if missing:
        line += f", {missing} missing (no C compiler at install? pip install -v shows why)"
    if built < n:
        line += "; numba or numpy serves the others"
    return line


def reset() -> None:
    """Forget the loaded libraries (tests: after switching :data:`ENV`)."""
    with _lock:
        _loaded.clear()


#: Extra flags of a sanitized build (``python -m roboisf.jit.native --sanitize``): run the
#: tests with ``LD_PRELOAD="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libubsan.so)"
#: ASAN_OPTIONS=detect_leaks=0``, then rebuild without it.
SANITIZE = [
    "-fsanitize=address,undefined,float-cast-overflow",
    "-fno-sanitize-recover=undefined",
    "-fno-omit-frame-pointer",
    "-g",
]


def build_inplace(
    package: Path = _PACKAGE,
    *,
    only: list[Path] | None = None,
    compiler: str | None = None,
    extra: list[str] | None = None,
) -> list[str]:
    """Compile every C kernel of ``package`` (or the sources ``only``) beside its source with
    :data:`CFLAGS` (and ``extra``) — the developer's quick rebuild, ``python -m
    roboisf.jit.native [--sanitize] [SOURCE.c ...]``; ``pip install`` builds the same extensions
    through setuptools. The failures, one line each."""
    import subprocess
    import sysconfig

    cc = compiler or os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc"
    include = sysconfig.get_paths()["include"]
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    failures = []
    wanted = None if not only else {p.resolve() for p in only}
    for name, source, sha in extensions(package):
        if wanted is not None and source.resolve() not in wanted:
            continue
        out = source.with_name(name.rsplit(".", 1)[1] + suffix)
        tmp = out.with_name(out.name + f".{os.getpid()}.tmp")
        cmd = [
            *cc.split(),
            *CFLAGS,
            *(extra or []),
            "-fPIC",
            "-shared",
            f"-I{include}",
            f'-DROBOISF_SOURCE_SHA256="{sha}"',
            str(source),
            "-o",
            str(tmp),
            "-lm",
        ]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            tmp.unlink(missing_ok=True)
            failures.append(f"{source}: {r.stderr.strip()}")
            continue
        os.replace(tmp, out)
    return failures


if __name__ == "__main__":  # pragma: no cover - a developer's command
    args = sys.argv[1:]
    sanitize = "--sanitize" in args
    problems = build_inplace(
        only=[Path(a) for a in args if a != "--sanitize"], extra=SANITIZE if sanitize else None
    )
    for line in problems:
        print(line, file=sys.stderr)
    sys.exit(1 if problems else 0)
