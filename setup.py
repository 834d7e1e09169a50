"""Build step of roboisf's install: its compiled kernels built with the package (pyproject.toml
holds everything else).

The C kernels (``src/roboisf/**/*_kernel.c``, :mod:`roboisf.jit.native`) are extension modules,
built by setuptools' ``build_ext`` with the flags of ``roboisf.jit.native.CFLAGS`` and the
SHA-256 of their source embedded; ``optional``: without a C compiler the install goes on, and the
numba kernels serve.

``build_kernels`` runs after ``build_py`` and ``build_ext`` in every build pip makes — a wheel
(into the package copied to ``build/lib``) and an editable install (into ``src``, editable
mode) — and compiles the numba kernels of the groups no C kernel serves (all of them without a
C compiler; every group for an editable install) into numba's cache beside its sources
(``python -m roboisf.jit.prebuild``; docs/speed.md, "Kernels built at install"). The build
environment has numba and what the kernels' modules import (``[build-system] requires``).

For an editable install it also compiles the package's Python bytecode, as pip does for an
installed one (and not for an editable one).

Never fatal: a failure prints its reason and the install goes on without the cache; the first
run then builds it in the background, as an install without this step did.
``ROBOISF_BUILD_KERNELS=0`` skips it.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path
from typing import Any, ClassVar

from setuptools import Command, Extension, setup
from setuptools.command.build import build
from setuptools.command.build_ext import build_ext

#: Longest the kernel build may take [s] before the install goes on without it (it takes
#: 10-40 s on 2 cores).
TIMEOUT_S = 900


class build_kernels(Command):  # setuptools names its commands in snake case
    """Compile roboisf's numba kernels (those no C kernel serves; all for an editable install)
    into the package's in-tree numba cache."""

    description = "compile roboisf's numba kernels into the package's numba cache"
    user_options: ClassVar[list[tuple[str, str | None, str]]] = []

    def initialize_options(self) -> None:
        self.build_lib: str | None = None
        self.editable_mode = False

    def finalize_options(self) -> None:
        self.set_undefined_options("build_py", ("build_lib", "build_lib"))

    def _root(self) -> Path:
        return Path("src").resolve() if self.editable_mode else Path(self.build_lib).resolve()

    def run(self) -> None:
        root = self._root()
        if self.editable_mode:
            # pip compiles an installed package's bytecode, not an editable one's: the first
            # command would compile every module it imports from source (0.3-0.5 s of a demo)
            import compileall

            compileall.compile_dir(str(root / "roboisf"), quiet=1)
        if os.environ.get("ROBOISF_BUILD_KERNELS", "1").strip() == "0":
            self.announce("roboisf kernels: not built (ROBOISF_BUILD_KERNELS=0)", level=2)
            return
        env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
        env["PYTHONPATH"] = os.pathsep.join([str(root), *filter(None, [env.get("PYTHONPATH")])])
        env["ROBOISF_BACKGROUND_COMPILE"] = "0"  # compile here; never start a builder
        env.pop("ROBOISF_NUMBA", None)
        try:
            r = subprocess.run(
                # a checkout's editable install builds every group: its tests run the C and
                # the numba forms side by side (a wheel: only the groups no C form serves)
                [
                    *(sys.executable, "-m", "roboisf.jit.prebuild", str(root)),
                    *(["--all"] if self.editable_mode else []),
                ],
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
                timeout=TIMEOUT_S,
            )
            out = r.stdout.strip()
        except (OSError, subprocess.TimeoutExpired) as e:
            out = f"roboisf kernels: not built ({e}); they will be built after the first run"
        for line in out.splitlines()[-20:]:
            print(line, file=sys.stderr)

    def get_outputs(self) -> list[str]:
        # numba names its files after each kernel; they are found after the build
        root = self._root() / "roboisf"
        return [str(p) for p in root.rglob("__pycache__/*.nb[ic]")]

    def get_source_files(self) -> list[str]:
        return []

    def get_output_mapping(self) -> dict[str, str]:
        return {}


class build_with_kernels(build):
    """``build`` with :class:`build_kernels` after its own steps (``build_py`` first)."""

    sub_commands: ClassVar[list[tuple[str, object]]] = [
        *build.sub_commands,
        ("build_kernels", None),
    ]


class build_ext_parallel(build_ext):
    """``build_ext`` compiling the C kernels side by side, one per core (setuptools' own
    ``--parallel``, which a user's ``-j`` still sets): eight sources of 0.3-1.3 s of ``-O3``
    each (nine since 2026-11-30), compiled one after another, were ~5 s of every install."""

    def finalize_options(self) -> None:
        super().finalize_options()
        if not self.parallel:
            self.parallel = max(1, min(os.cpu_count() or 1, len(self.extensions or [])))


cmdclass: dict[str, type] = {
    "build": build_with_kernels,
    "build_kernels": build_kernels,
    "build_ext": build_ext_parallel,
}

try:  # setuptools ≥ 70.1 has bdist_wheel itself; older: the wheel keeps the pure tag
    from setuptools.command.bdist_wheel import bdist_wheel
except ImportError:  # pragma: no cover
    bdist_wheel = None

if bdist_wheel is not None:

    class bdist_wheel_with_kernels(bdist_wheel):
        """A wheel that carries compiled kernels is not pure Python: numba's cache is for this
        Python (``py311`` in its file names) and platform, so the wheel is tagged for them
        (``cp311-cp311-linux_x86_64``) and pip does not take it for another Python. Pure, as
        before, when the kernels were not built."""

        def get_tag(self) -> tuple[str, str, str]:
            if any(Path(self.bdist_dir).rglob("__pycache__/*.nbi")):
                self.root_is_pure = False
            return super().get_tag()

    cmdclass["bdist_wheel"] = bdist_wheel_with_kernels


def _native() -> Any:
    """``roboisf.jit.native`` loaded on its own (standard library only; the package's other
    modules need what the build environment may not have)."""
    path = Path(__file__).resolve().parent / "src" / "roboisf" / "jit" / "native.py"
    spec = importlib.util.spec_from_file_location("_roboisf_native_build", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def c_extensions() -> list[Extension]:
    """Every C kernel as an optional extension module (``roboisf.scan._knn_kernel_c`` from
    ``src/roboisf/scan/knn_kernel.c``)."""
    native = _native()
    root = Path(__file__).resolve().parent
    return [
        Extension(
            name,
            sources=[str(source.relative_to(root))],
            extra_compile_args=list(native.CFLAGS),
            define_macros=[("ROBOISF_SOURCE_SHA256", f'"{sha}"')],
            libraries=["m"],
            optional=True,
        )
        for name, source, sha in native.extensions(root / "src" / "roboisf")
    ]


if __name__ == "__main__":  # as setuptools runs it (importable by tests/test_install_kernels.py)
    setup(cmdclass=cmdclass, ext_modules=c_extensions())
