"""The command line starts at once (issue #16): ``--help``, every command's ``--help`` and the
argument checks that fail before any computation load neither numpy nor the libraries built on it.

Not a timing test: the check is which modules a fresh interpreter has loaded, which does not
depend on the machine's load. The lazy packages that make this possible must still give the same
objects as their modules.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import roboisf

HEAVY = ("numpy", "pandas", "scipy", "numba", "plotly", "matplotlib", "pyarrow", "trimesh")

# (argv, expected exit code); the bad inputs are refused from the arguments alone
RUNS: list[tuple[list[str], int]] = [
    (["--help"], 0),
    (["--version"], 0),
    (["part", "--help"], 0),
    (["part", "cone", "--help"], 0),
    (["toolpath", "--help"], 0),
    (["toolpath", "cone", "--help"], 0),
    (["plan", "--help"], 0),
    (["robot", "deflect", "--help"], 0),
    (["analyze", "--help"], 0),
    (["compensate", "--help"], 0),
    (["demo", "--help"], 0),
    (["tool-stiffness", "--help"], 0),
    (["scan", "compare", "--help"], 0),
    (["part", "cone", "-o", "cone.txt"], 2),  # a part file must end in .toml
    (["toolpath", "cone", "-o", "path.xyz"], 2),  # unknown format suffix
    (["toolpath", "cone", "-o", "path.csv", "--step-down", "-1"], 2),
]

# one interpreter runs every argv in turn and records what was loaded after each (the union must
# stay empty, so running them together checks as much as one process each, and costs one start)
_CHILD = """
import contextlib, io, json, sys
from roboisf.cli.main import main
heavy = set(json.loads(sys.argv[2]))
out = []
for argv in json.loads(sys.argv[1]):
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = main(argv)
    out.append({"code": code, "heavy": sorted({m.split(".")[0] for m in sys.modules} & heavy)})
print(json.dumps(out))
"""


def _child(code: str, *args: str, cwd: Path | None = None) -> object:
    # the child runs in another folder: give it this roboisf, not whatever an install provides
    src = str(Path(roboisf.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run(
        [sys.executable, "-c", code, *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
        env=env,
    )
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_importing_the_cli_loads_no_numeric_library():
    loaded = "sorted({m.split('.')[0] for m in sys.modules} & set(json.loads(sys.argv[1])))"
    code = f"import json, sys; import roboisf.cli.main; print(json.dumps({loaded}))"
    assert _child(code, json.dumps(HEAVY)) == []


def test_help_and_argument_errors_load_no_numeric_library(tmp_path):
    out = _child(_CHILD, json.dumps([a for a, _ in RUNS]), json.dumps(HEAVY), cwd=tmp_path)
    got = {" ".join(a): (o["code"], o["heavy"]) for (a, _), o in zip(RUNS, out, strict=True)}
    assert got == {" ".join(a): (code, []) for a, code in RUNS}
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_a_command_that_runs_still_loads_what_it_needs(tmp_path):
    # the guard above is not vacuous: building a part does import numpy in the same harness
    out = _child(
        _CHILD, json.dumps([["part", "cone", "-o", "c.toml"]]), json.dumps(HEAVY), cwd=tmp_path
    )
    assert out == [{"code": 0, "heavy": ["numba", "numpy", "scipy"]}]
    assert (tmp_path / "c.toml").is_file()


@pytest.mark.parametrize("package", ["roboisf.parts", "roboisf.toolpath", "roboisf.io"])
def test_lazy_packages_export_the_objects_of_their_modules(package):
    pkg = importlib.import_module(package)
    for name in pkg.__all__:
        value = getattr(pkg, name)
        module = importlib.import_module(f"{package}.{pkg._MODULE_OF[name]}")
        assert value is getattr(module, name), name
        assert name in dir(pkg)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        pkg.nope  # noqa: B018


def test_light_default_modules_match_the_geometry():
    from roboisf.parts import axisymmetric, defaults
    from roboisf.toolpath import generate, limits

    assert axisymmetric.PAPER_SHEET_THICKNESS is defaults.PAPER_SHEET_THICKNESS == 1.22e-3
    assert axisymmetric.VWACF_DEFAULT_ARC_RADIUS is defaults.VWACF_DEFAULT_ARC_RADIUS
    assert generate.MAX_POINTS is limits.MAX_POINTS
