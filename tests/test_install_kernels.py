"""Kernels built at install (issue #31): pip builds roboisf's wheel; its C kernels are built as
extension modules, and setup.py's build_kernels step compiles into numba's cache beside the
package's sources the kernel groups no C kernel serves (none where a compiler is; all without
one; all for a checkout's editable install, ``--all``). The installed package's first analyze
and plan run compiled (no background builder, nothing compiled on first use). The wheel is built
as pip builds it (`pip wheel`), without build isolation: the test venv holds what
[build-system] requires lists, and no package index is needed.

The numba fallback is checked on the caches this checkout's install built (every group, from an
empty cache: `pip install -e .` on CI): building them again in a wheel took this module 46 CPU-s
of the suite's ~470 (2026-11-30)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from roboisf import jit
from roboisf.jit.prebuild import in_tree_missing
from test_jit import SRC, _signatures

needs_numba = pytest.mark.skipif(not jit.HAVE_NUMBA, reason="numba not installed")

_READY = """
import json, roboisf
from roboisf.jit import background as bg
print(json.dumps({"file": roboisf.__file__, "ready": {g: bg.ready(g) for g in bg.GROUPS}}))
"""


#: ``roboisf -q ARGS...`` through the console script's entry, then whether numba was imported.
_NO_NUMBA = """
import atexit, sys
atexit.register(lambda: print("numba imported:", "numba" in sys.modules))
from roboisf.cli.main import entry
sys.argv = ["roboisf", "-q", *sys.argv[1:]]
entry()
"""


def _project_copy(dest: Path) -> Path:
    """The project's build inputs copied to ``dest`` (no caches, no build folder)."""
    dest.mkdir()
    for name in ("pyproject.toml", "setup.py", "README.md"):
        shutil.copy2(SRC.parents[1] / name, dest / name)
    shutil.copytree(
        SRC,
        dest / "src" / "roboisf",
        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc", "*.so", "*.tmp"),
    )
    return dest


def _installed_env(package_root: Path, tmp_path: Path) -> dict[str, str]:
    """The environment of a user's run of the package under ``package_root``: background
    building on, no cache folder of numba's set, its own temp folder (where a builder's lock
    would appear)."""
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env.update(PYTHONPATH=str(package_root), ROBOISF_BACKGROUND_COMPILE="1", TMPDIR=str(tmp_path))
    return env


def _plan_args(env: dict[str, str], tmp_path: Path, out: Path) -> list[str]:
    """``roboisf plan`` of a cone (its part file written first, with ``env``) into ``out``."""
    part = tmp_path / "cone.toml"
    if not part.exists():
        subprocess.run(
            [sys.executable, "-m", "roboisf", "-q", "part", "cone", "-o", str(part)],
            env=env,
            check=True,
            capture_output=True,
            timeout=600,
        )
    plan = [*("plan", "--part", str(part), "--x-range", "2000:2200:2", "--y-range", "-500")]
    return [*plan, "--z-range", "200", "--serial", "-o", str(out)]


@pytest.mark.slow
def test_the_wheel_carries_its_kernels_and_the_first_run_compiles_nothing(
    tmp_path, fast_cone_study
):
    """A wheel built where a C compiler is: every C kernel built and in the wheel, no numba
    kernel compiled (the C forms serve every group); installed, its first analyze and plan run
    the C forms, import no numba and start no builder."""
    proj = _project_copy(tmp_path / "proj")
    wheels = tmp_path / "wheels"
    env = dict(os.environ)
    # a user's cache folder is not where the package's kernels go: the step must ignore it
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "users-cache")
    env.pop("PYTHONPATH", None)
    r = subprocess.run(
        [
            *(sys.executable, "-m", "pip", "wheel", "-v", "--no-deps", "--no-build-isolation"),
            *("-w", str(wheels), str(proj)),
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    # the step ran and said why it compiled nothing (numba installed or not: it is not needed)
    assert "the C kernels serve every group; no numba kernel built" in r.stdout + r.stderr
    (whl,) = wheels.glob("roboisf-*.whl")
    # not pure Python: its C kernels are for this Python and platform
    assert f"-cp{sys.version_info[0]}{sys.version_info[1]}-" in whl.name, whl.name
    with zipfile.ZipFile(whl) as z:
        names = z.namelist()
        assert not [n for n in names if n.endswith((".nbi", ".nbc"))]  # no numba kernel
        site = tmp_path / "site"
        z.extractall(site)
    assert not (tmp_path / "users-cache").exists()
    # every C kernel is built, with its source (roboisf.jit.native checks one by the other)
    sources = sorted(p.relative_to(SRC.parent) for p in SRC.rglob("*_kernel.c"))
    assert sources
    for c in sources:
        assert (site / c).is_file()
        assert list((site / c).parent.glob(f"_{c.stem}_c.*.so")), f"{c}: no library in the wheel"

    # the installed package, as a user runs it
    run_env = _installed_env(site, tmp_path)
    probe = json.loads(
        subprocess.run(
            [sys.executable, "-c", _READY], env=run_env, check=True, capture_output=True, text=True
        ).stdout
    )
    assert Path(probe["file"]).resolve().is_relative_to(site.resolve())
    assert all(probe["ready"].values()), probe["ready"]  # compiled at once: no builder
    plan = _plan_args(run_env, tmp_path, tmp_path / "plan")
    for args in (["analyze", str(fast_cone_study), "-o", str(tmp_path / "analysis")], plan):
        r = subprocess.run(
            [sys.executable, "-c", _NO_NUMBA, *args],
            env=run_env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert r.returncode == 0, r.stderr[-3000:]
        assert r.stdout.strip() == "numba imported: False", args[0]  # the C kernels ran
    assert (tmp_path / "analysis" / "summary.json").is_file()
    assert (tmp_path / "plan" / "plan.json").is_file()
    assert not list(tmp_path.glob("roboisf-kernel-build-*"))  # no builder was started
    assert not list(site.rglob("*.nbi"))  # and nothing was compiled into the install


@needs_numba
def test_the_numba_fallback_built_at_install_serves_every_command_compiling_nothing(
    tmp_path, fast_cone_study
):
    """Every numba kernel group the install builds (a wheel without a C compiler; every
    checkout's editable install, ``--all``) serves analyze, plan and compensate without
    compiling a thing (and with the C forms none imports numba):
    each specialisation they call is one the build step made (it had missed row_norms of a log
    read backwards and plan's whole inner loop, 2026-11-29: the first analyze after it compiled
    for 0.2 s, the first plan for ~1.5 s), with the same bytes as the C forms. Run on a copy of
    this checkout's package with the caches its install built (numba finds a cache by the
    source's SHA-256, so the copy keeps it), so a compile writes into the copy and is seen."""
    missing = in_tree_missing(SRC.parent)
    assert missing == [], (
        f"the install built no numba kernels for {missing}: reinstall (`pip install -e .`, "
        "setup.py builds every group for an editable install)"
    )
    root = tmp_path / "pkg"
    shutil.copytree(SRC, root / "roboisf", ignore=shutil.ignore_patterns("*.pyc", "*.tmp"))
    assert in_tree_missing(root) == []
    built = _signatures(root)
    run_env = _installed_env(root, tmp_path)
    for native in ("1", "0"):
        out = tmp_path / f"native{native}"
        plan = _plan_args(run_env, tmp_path, out / "plan")
        comp = ["compensate", "--virtual", "cone", "--step-down", "2", "--spacing", "3"]
        comp += ["--iterations", "2", "--no-png", "-o", str(out / "comp")]
        analysis = ["analyze", str(fast_cone_study), "-o", str(out / "analysis")]
        for args in (analysis, plan, comp):
            r = subprocess.run(
                [sys.executable, "-c", _NO_NUMBA, *args],
                env={**run_env, "ROBOISF_NATIVE": native},
                capture_output=True,
                text=True,
                timeout=600,
            )
            assert r.returncode == 0, r.stderr[-3000:]
            assert r.stdout.strip() == f"numba imported: {native == '0'}", args[0]
    assert not list(tmp_path.glob("roboisf-kernel-build-*"))  # no builder was started
    missed = _signatures(root) - built
    assert not missed, f"a command compiled what the install did not: {sorted(missed)}"
    # the two compiled forms, the same numbers
    comp = ["compensated.csv", "compensated.mod", "compensated.src", "per_point.csv"]
    comp += ["compensated.ls", "compensated.nc", "compensation.json"]
    for name in [
        "analysis/contributions.csv",
        "plan/placements.csv",
        "plan/plan.json",
        *(f"comp/{n}" for n in comp),
    ]:
        assert (tmp_path / "native1" / name).read_bytes() == (
            tmp_path / "native0" / name
        ).read_bytes(), name


def test_the_build_step_can_be_switched_off_and_fails_softly(tmp_path):
    """``ROBOISF_BUILD_KERNELS=0`` skips the step; a wrong root or a set NUMBA_CACHE_DIR is a
    printed reason and exit 1 (setup.py prints it and the install goes on), never a traceback."""
    base = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}

    def run(root: Path, **extra: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "roboisf.jit.prebuild", str(root)],
            env={**base, **extra},
            capture_output=True,
            text=True,
        )

    off = run(tmp_path, ROBOISF_BUILD_KERNELS="0")
    assert off.returncode == 0 and "not built (ROBOISF_BUILD_KERNELS=0)" in off.stdout
    cache_set = run(tmp_path, NUMBA_CACHE_DIR=str(tmp_path / "c"))
    assert cache_set.returncode == 1 and "NUMBA_CACHE_DIR is set" in cache_set.stdout
    if jit.HAVE_NUMBA:
        wrong = run(tmp_path)  # roboisf is imported from the checkout, not from tmp_path
        assert wrong.returncode == 1 and "not from" in wrong.stdout, wrong.stdout
        assert "Traceback" not in wrong.stdout + wrong.stderr
    assert not any(tmp_path.rglob("*.nbi"))


def test_an_editable_install_gets_its_bytecode_compiled(tmp_path, monkeypatch):
    """pip compiles an installed package's bytecode but not an editable one's: the build step
    does it (in editable mode it works on the sources themselves), with or without kernels."""
    import importlib.util

    from setuptools import Distribution

    spec = importlib.util.spec_from_file_location("roboisf_setup", SRC.parents[1] / "setup.py")
    assert spec is not None and spec.loader is not None
    setup_py = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(setup_py)  # defines the commands; setup() runs only as __main__
    root = _project_copy(tmp_path / "proj") / "src"
    cmd = setup_py.build_kernels(Distribution({"name": "roboisf"}))
    cmd.initialize_options()
    cmd.editable_mode = True
    monkeypatch.setattr(cmd, "_root", lambda: root)
    monkeypatch.setenv("ROBOISF_BUILD_KERNELS", "0")  # the bytecode alone
    cmd.run()
    sources = list((root / "roboisf").rglob("*.py"))
    tag = sys.implementation.cache_tag
    compiled = [p for p in sources if (p.parent / "__pycache__" / f"{p.stem}.{tag}.pyc").is_file()]
    assert len(compiled) == len(sources) > 100
    assert not any((root / "roboisf").rglob("*.nbi"))  # no kernels: switched off


@needs_numba
def test_the_build_step_compiles_the_groups_no_c_kernel_serves_or_all_when_asked(
    monkeypatch, capsys
):
    """``python -m roboisf.jit.prebuild ROOT``: nothing where the C forms serve every group;
    the groups they do not serve where one is missing (no C compiler: the wheel's numba
    fallback); every group with ``--all`` (setup.py passes it for an editable install)."""
    from roboisf.jit import background, prebuild

    calls: list[bool] = []
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.delenv(prebuild.SKIP_ENV, raising=False)
    monkeypatch.setenv(background.ENV, "1")  # as a hand-run has it: the step switches it off
    monkeypatch.setattr(
        background, "build_missing", lambda *, skip_native: calls.append(skip_native) or []
    )
    root = str(SRC.parent)  # this checkout: its C kernels and its install's numba caches
    assert all(background.native_ready(g) for g in background.GROUPS)
    assert prebuild.main([root]) == 0 and calls == []
    assert "the C kernels serve every group; no numba kernel built" in capsys.readouterr().out
    assert prebuild.main([root, "--all"]) == 0 and calls == [False]
    # compiled in the foreground: a kernel whose caller asks jit.ready is compiled, not
    # left to a background builder (the online loop's and the position alignment's were)
    assert os.environ[background.ENV] == "0"
    ready = background.native_ready
    monkeypatch.setattr(background, "native_ready", lambda g: g != "scan" and ready(g))
    assert prebuild.main([root]) == 0 and calls == [False, True]
    assert "built in" in capsys.readouterr().out
    assert prebuild.main([]) == 2
