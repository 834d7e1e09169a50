"""gmsh meshes in a process of its own (roboisf.fem.mesh._mesh_in_child): the same mesh to the
bit, the caller's process left as it was (gmsh.initialize raises the stack limit to the hard
limit and resets SIGPIPE for the whole process), and what the meshing process answers — an
input error, a crash, a bug — arrives as one exception here."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.fem import BallEndTool
from roboisf.fem.mesh import _mesh_here, mesh_geometry

TOOL = BallEndTool(10e-3, 30e-3)
H = 3e-3  # gmsh repeats this mesh to the bit (at 5 mm it does not, even in one process)
ARRAYS = ("points", "tets", "body", "clamped", "coupling")


def _same(a: Any, b: Any) -> bool:
    return a.mesh_size == b.mesh_size and all(
        np.array_equal(getattr(a, k), getattr(b, k)) for k in ARRAYS
    )


def test_the_mesh_from_its_own_process_is_the_in_process_mesh():
    a, b = mesh_geometry(TOOL, H), _mesh_here(TOOL, H)
    assert a.n_nodes > 100
    assert _same(a, b)


def test_meshing_leaves_the_callers_process_as_it_was():
    """In a fresh interpreter: after mesh_geometry, gmsh was never loaded there, and the stack
    limit (which gmsh.initialize raises to the hard limit, inherited by every later child
    process) and SIGPIPE's disposition are what they were."""
    code = textwrap.dedent(
        """
        import resource, signal, sys
        from roboisf.fem import BallEndTool
        from roboisf.fem.mesh import mesh_geometry
        resource.setrlimit(resource.RLIMIT_STACK, (8 << 20, resource.RLIM_INFINITY))
        before = resource.getrlimit(resource.RLIMIT_STACK), signal.getsignal(signal.SIGPIPE)
        mesh_geometry(BallEndTool(10e-3, 30e-3), 5e-3)
        after = resource.getrlimit(resource.RLIMIT_STACK), signal.getsignal(signal.SIGPIPE)
        print("gmsh" in sys.modules, before == after, after)
        """
    )
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1] / "src")}
    p = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env
    )
    assert p.returncode == 0, p.stderr
    assert p.stdout.split()[:2] == ["False", "True"], p.stdout


@dataclass(frozen=True)
class _Failing:
    """The tool, with a build that ends the meshing process by ``how``."""

    how: str
    tool: BallEndTool = TOOL

    def __getattr__(self, name: str) -> Any:
        return getattr(self.tool, name)

    def build(self, occ: Any, model: Any) -> Any:
        if self.how == "abort":
            os.kill(os.getpid(), signal.SIGABRT)
        if self.how == "bug":
            return 1 / 0
        raise InputError("no such face", field="faces")


@pytest.fixture
def child_imports_tests(monkeypatch):
    """The meshing process can import this module (the geometry's class)."""
    here = str(Path(__file__).parent)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([here, os.environ.get("PYTHONPATH", "")]))


def test_a_crash_of_gmsh_is_one_line_and_the_caller_lives(child_imports_tests):
    with pytest.raises(InputError) as e:
        mesh_geometry(_Failing("abort"), H)
    assert e.value.field == "geometry"
    assert "ended by SIGABRT" in str(e.value) and "\n" not in str(e.value)


def test_an_input_error_of_the_meshing_process_arrives_whole(child_imports_tests):
    with pytest.raises(InputError, match="no such face") as e:
        mesh_geometry(_Failing("input"), H)
    assert e.value.field == "faces"


def test_a_bug_in_the_meshing_process_shows_its_traceback(child_imports_tests):
    with pytest.raises(RuntimeError, match="ZeroDivisionError"):
        mesh_geometry(_Failing("bug"), H)


@dataclass(frozen=True)
class _Wrapped:
    """The tool under a class the meshing process cannot import (tests/ not on its path)."""

    tool: BallEndTool = TOOL

    def __getattr__(self, name: str) -> Any:
        return getattr(self.tool, name)


def test_a_geometry_only_this_process_knows_is_meshed_here(monkeypatch):
    @dataclass(frozen=True)
    class Local(_Wrapped):  # not picklable at all
        pass

    monkeypatch.delenv("PYTHONPATH", raising=False)
    for geometry in (_Wrapped(), Local()):
        assert _same(mesh_geometry(geometry, H), _mesh_here(TOOL, H))


def test_a_module_in_the_current_folder_does_not_stand_in_for_gmsh(tmp_path, monkeypatch):
    """The meshing process starts with ``-P``: a ``gmsh.py`` in the caller's folder is not
    imported in place of gmsh."""
    (tmp_path / "gmsh.py").write_text("raise SystemExit('not gmsh')\n")
    monkeypatch.chdir(tmp_path)
    assert _same(mesh_geometry(TOOL, H), _mesh_here(TOOL, H))
