"""-q/-v after the command, the compile notice of the compiled kernels, the end of analyze's
output (verdicts, next command) and the part file's numbers (issue #30)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from roboisf import jit, progress
from roboisf.cli.analyze import _print_verdicts, next_command
from roboisf.cli.console import state
from roboisf.cli.main import hoist_verbosity, main


def test_hoist_moves_the_flags_in_front_but_not_after_double_dash():
    assert hoist_verbosity(["analyze", "s", "-v"]) == ["-v", "analyze", "s"]
    assert hoist_verbosity(["-q", "part", "cone"]) == ["-q", "part", "cone"]
    assert hoist_verbosity(["part", "--quiet", "cone", "--", "-v"]) == [
        "--quiet",
        "part",
        "cone",
        "--",
        "-v",
    ]


@pytest.mark.parametrize("where", ["before", "after"])
def test_quiet_works_before_and_after_the_command(where, tmp_path, capsys):
    out = tmp_path / "c.toml"
    args = ["part", "cone", "-o", str(out)]
    assert main(["-q", *args] if where == "before" else [*args, "-q"]) == 0
    assert capsys.readouterr().out == ""
    assert main([*args, "--overwrite"]) == 0
    assert "wrote" in capsys.readouterr().out  # without -q it prints: the test can fail


def test_part_file_numbers_have_no_binary_noise(tmp_path):
    out = tmp_path / "c.toml"
    assert main(["part", "cone", "-o", str(out), "-q"]) == 0
    text = out.read_text()
    assert "opening_diameter = 87.0\n" in text and "0000000" not in text
    from roboisf.parts import load_part

    assert load_part(out).to_dict()["opening_diameter"] == pytest.approx(87.0, rel=1e-12)


def _module(tmp_path: Path) -> Path:
    src = tmp_path / "pkg" / "kern.py"
    src.parent.mkdir()
    src.write_text("x = 1\n")
    return src


def test_kernel_cached_reads_the_numba_index_beside_the_module(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    src = _module(tmp_path)
    assert not jit.kernel_cached(src)
    index = src.parent / "__pycache__" / "kern._rows-33.py311.nbi"
    index.parent.mkdir()
    index.write_text("")
    assert jit.kernel_cached(src)
    old = time.time() - 100
    os.utime(index, (old, old))  # older than the source: numba recompiles
    assert not jit.kernel_cached(src)


def test_kernel_cached_reads_numba_cache_dir(tmp_path, monkeypatch):
    """The layout numba itself writes under $NUMBA_CACHE_DIR (``<folder>_<sha1 of its path>``),
    checked against a real cached compile, not a hand-made folder."""
    pytest.importorskip("numba")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    src = tmp_path / "pkg" / "kern.py"
    src.parent.mkdir()
    src.write_text("import numba\n\n@numba.njit(cache=True)\ndef f(x):\n    return x + 1\n")
    cache = tmp_path / "nbcache"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    assert not jit.kernel_cached(src)
    env = dict(os.environ, PYTHONPATH=str(src.parent))
    subprocess.run([sys.executable, "-c", "import kern; kern.f(1)"], env=env, check=True)
    assert jit.kernel_cached(src)


def test_with_background_building_the_first_notice_is_the_builders(tmp_path, monkeypatch):
    """Importing an uncached kernel module compiles nothing when the builder builds: no "first
    time, minutes" notice then (it was the run's one notice, claiming a wait that did not come
    and keeping the builder's from being said); the builder's notice is the one said."""
    from roboisf.jit import background as bg

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv(bg.ENV, "1")
    monkeypatch.setattr(bg, "_started", False)
    monkeypatch.setattr(bg, "failure_path", lambda: tmp_path / "none.failed")
    monkeypatch.setattr(bg, "lock_path", lambda: tmp_path / "b.lock")
    monkeypatch.setattr(bg.subprocess, "Popen", lambda *a, **k: None)  # no real builder
    said: list[str] = []
    progress.set_notice(said.append)
    try:
        jit.compile_notice(_module(tmp_path))
        assert said == []
        bg._start()
        assert len(said) == 1 and "in the background" in said[0] and "numpy" in said[0]
    finally:
        progress.set_notice(None)


def _kernel_module(tmp_path: Path, name: str) -> Any:
    """A kernel module as roboisf writes one (compile_notice at import, two numba kernels),
    imported from ``tmp_path``."""
    src = tmp_path / f"{name}.py"
    src.write_text(
        "from roboisf.jit import compile_notice, njit\n"
        "compile_notice(__file__)\n"
        "@njit()\n"
        "def f(x):\n"
        "    return x + 1\n"
        "@njit()\n"
        "def g(x):\n"
        "    return x + 2\n"
    )
    spec = importlib.util.spec_from_file_location(name, src)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_compile_notice_once_when_a_kernel_compiles_and_only_when_not_cached(tmp_path, monkeypatch):
    from roboisf.jit import background as bg

    monkeypatch.setenv(bg.ENV, "0")  # compiling in the foreground: the notice's case
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    said: list[str] = []
    progress.set_notice(said.append)
    try:
        m = _kernel_module(tmp_path, "kern_notice")
        assert said == []  # importing compiles nothing: nothing said (its C form may serve)
        assert m.f(1) == 2
        assert len(said) == 1 and "first time" in said[0] and "minutes" in said[0]
        assert m.g(1) == 3  # the module's second kernel: said once
        assert len(said) == 1
        progress.set_notice(said.append)  # a new run: the cache is there now
        m = _kernel_module(tmp_path, "kern_notice")
        assert m.f(1) == 2
        assert len(said) == 1
    finally:
        progress.set_notice(None)
    jit.compile_notice(tmp_path / "other.py")  # no hook: silent, no error


def _summary(**extra):
    return {
        "study": "s",
        "warnings": ["the robot model does not hold: use identified_stiffness.toml"],
        "vjm_check": {"ratio": 2.0, "ci_low": 1.98, "ci_high": 2.02, "verdict": "mismatch"},
        "identified_stiffness": "identified_stiffness.toml",
        **extra,
    }


def test_next_command_uses_the_identified_stiffness_on_a_mismatch():
    cmd = next_command(_summary(), Path("st"), Path("res"))
    assert cmd == (
        "roboisf compensate st --results res --stiffness res/identified_stiffness.toml "
        "-o compensated"
    )
    ok = _summary(vjm_check={"ratio": 1.0, "verdict": "consistent"})
    assert "--stiffness" not in next_command(ok, Path("st"), Path("res"))


def test_analyze_ends_with_verdicts_warnings_and_the_next_command(capsys):
    state.verbosity = 1
    diag = [
        {
            "suspect": "robot_stiffness",
            "verdict": "fault",
            "estimate": 0.5,
            "ci_low": 0.49,
            "ci_high": 0.51,
            "unit": "× nominal",
            "explanation": "softer",
        },
        {
            "suspect": "force_bias",
            "verdict": "ok",
            "estimate": 0.1,
            "ci_low": -1,
            "ci_high": 1,
            "unit": "N",
            "explanation": "none",
        },
    ]
    _print_verdicts(_summary(diagnosis=diag), Path("st"), Path("res"))
    cap = capsys.readouterr()
    assert "mismatch" not in cap.out  # said in words
    assert (
        "model check: the robot model does not hold: measured / VJM robot deflection 2.00"
        in cap.out
    )
    assert "diagnosis: robot joint stiffness — fault, 0.500 [0.490, 0.510] × nominal" in cap.out
    assert "force sensor bias" not in cap.out  # 'ok' suspects stay in the report
    assert "measured study" in cap.out
    assert cap.out.rstrip().splitlines()[-1].startswith("next: roboisf compensate st")
    assert "identified_stiffness.toml" in cap.err  # the warning reaches the terminal


def test_a_fault_outside_the_robot_says_check_it_first(capsys):
    state.verbosity = 1
    diag = [{"suspect": "scan_shift", "verdict": "fault", "estimate": 0.3, "unit": "mm"}]
    _print_verdicts(_summary(diagnosis=diag), Path("st"), Path("res"))
    last = capsys.readouterr().out.rstrip().splitlines()[-1]
    assert last.startswith("next: check the scan shift the diagnosis names")
    assert last.endswith(
        "roboisf compensate st --results res --stiffness "
        "res/identified_stiffness.toml -o compensated"
    )


def test_quiet_silences_the_verdicts(capsys):
    state.verbosity = 0
    try:
        _print_verdicts(_summary(), Path("st"), Path("res"))
    finally:
        state.verbosity = 1
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == ""


def test_toolpath_names_every_file_it_writes(tmp_path, capsys):
    """A KRL program is two files (.src and .dat): the line says so instead of naming one."""
    out = tmp_path / "tp.src"
    args = ["toolpath", "cone", "--step-down", "4", "--spacing", "4"]
    assert main([*args, "--placement", "1800,0,600", "--tool", "300", "-o", str(out)]) == 0
    line = capsys.readouterr().out
    assert (tmp_path / "tp.dat").is_file()
    assert "and 1 more file beside it (tp.dat)" in line
    csv = tmp_path / "tp.csv"
    assert main([*args, "-o", str(csv)]) == 0
    assert "more file" not in capsys.readouterr().out
