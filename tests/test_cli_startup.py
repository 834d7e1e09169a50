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
from roboisf.cli.lazy import load_command

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
    (["virtual-cell", "--help"], 0),
    (["holder-stiffness", "--help"], 0),
    (["online", "--help"], 0),
    (["study", "--help"], 0),
    (["study", "init", "--help"], 0),
    (["toolpath", "import", "--help"], 0),
    (["robot", "list", "--help"], 0),
    (["robot", "show", "--help"], 0),
    (["robot", "identify", "--help"], 0),
    (["part", "vwacf", "--help"], 0),
    (["part", "profile", "--help"], 0),
    (["part", "pyramid", "--help"], 0),
    (["part", "mesh", "--help"], 0),
    (["toolpath", "vwacf", "--help"], 0),
    (["toolpath", "profile", "--help"], 0),
    (["--bogus"], 2),  # usage errors: unknown option, unknown command, missing argument
    (["no-such-command"], 2),
    (["analyze"], 2),
    (["part", "cone", "-o", "cone.txt"], 2),  # a part file must end in .toml
    (["toolpath", "cone", "-o", "path.xyz"], 2),  # unknown format suffix
    (["toolpath", "cone", "-o", "path.csv", "--step-down", "-1"], 2),
    # a mistyped STUDY is reported before the numeric stack loads (was 2.8–3.3 s, now ~0.3 s)
    (["analyze", "no-such-study"], 2),
    (["analyze", "."], 2),  # a folder without study.toml
    (["compensate", "no-such-study"], 2),
    (["plan", "--study", "no-such-study"], 2),
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
    # (numpy only: part kinds are registered formats, so writing a cone no longer imports the
    # mesh part's numba and scipy through parts/io.py)
    assert out == [{"code": 0, "heavy": ["numpy"]}]
    assert (tmp_path / "c.toml").is_file()


def test_robot_list_and_show_load_numpy_only(tmp_path):
    # a preset's limits and stiffness: no identification tables (pandas, pyarrow) and no scipy
    # (scipy's Rotation is imported by the conversions that use it): 0.6 → 0.2 s, 148 → 49 MB
    runs = [["robot", "list"], ["-q", "robot", "show", "--robot", "irb7600-500-2.55"]]
    out = _child(_CHILD, json.dumps(runs), json.dumps(HEAVY), cwd=tmp_path)
    assert out == [{"code": 0, "heavy": ["numpy"]}] * 2


def test_a_robot_stiffness_map_does_not_start_numba(tmp_path):
    # a 41 × 41 map on numpy: 6 ms, where loading numba for it took 0.48 s and 120 MB
    runs = [["-q", "robot", "show", "--robot", "irb7600-500-2.55", "-o", "map.png"]]
    out = _child(_CHILD, json.dumps(runs), json.dumps(HEAVY), cwd=tmp_path)
    assert out[0]["code"] == 0 and "numba" not in out[0]["heavy"], out
    assert (tmp_path / "map.png").is_file()


def test_reading_a_study_loads_no_table_or_plotting_library(small_cone_study):
    # a study's check (log formats, robot preset, part) needs the file-format registry, not the
    # readers: no pandas, pyarrow, scipy.spatial/sparse or plotting library until the analysis
    code = (
        "import json, sys\n"
        "from roboisf.study import load_study\n"
        "s = load_study(sys.argv[1])\n"
        "assert s.has_cnc and s.robot_run.forces.format == 'auto'\n"
        "mods = ('pandas', 'pyarrow', 'scipy.spatial', 'scipy.sparse', 'matplotlib', 'plotly')\n"
        "print(json.dumps(sorted(m for m in mods if m in sys.modules)))\n"
    )
    assert _child(code, str(small_cone_study)) == []


def test_reading_a_study_s_files_loads_no_pandas(small_cone_study):
    """The files an analysis reads before and beside its scans — the toolpath CSV, the Parquet
    force and joint logs, a virtual cell's truth — are read without pandas (Arrow, numpy): its
    ~47 MB come after the scans' peak, with the tables (issue #31)."""
    code = (
        "import json, sys\n"
        "from pathlib import Path\n"
        "from roboisf.decompose import pipeline as pl\n"
        "from roboisf.study import load_study\n"
        "s = load_study(sys.argv[1])\n"
        "cell = pl.cell_from_study(s)\n"
        "tp = pl.study_toolpath(s, s.cnc, cell.part)\n"
        "log = pl.read_run_force_log(s, s.robot_run)\n"
        "joints = pl.read_run_joint_log(s.robot_run)\n"
        "truth = pl._read_truth(Path(sys.argv[1]) / 'truth' / 'per_point.parquet')\n"
        "assert len(tp) > 100 and len(log) > 1000 and joints.q.shape[0] > 100 and truth.num_rows\n"
        "print(json.dumps(sorted(m for m in ('pandas',) if m in sys.modules)))\n"
    )
    assert _child(code, str(small_cone_study)) == []


@pytest.mark.parametrize(
    "package",
    [
        "roboisf.parts",
        "roboisf.toolpath",
        "roboisf.io",
        "roboisf.cam",
        "roboisf.logs",
        "roboisf.study",
        "roboisf.robot",
        "roboisf.online",
        "roboisf.compensate",
    ],
)
def test_lazy_packages_export_the_objects_of_their_modules(package):
    pkg = importlib.import_module(package)
    for name in pkg.__all__:
        value = getattr(pkg, name)
        module = importlib.import_module(f".{pkg._MODULE_OF[name]}", package)
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


# ---------------------------------------------------------------------------------------------
# the lazy command registry (roboisf.cli.lazy): --help lists commands from a table in
# roboisf.cli.main; the table must say what the modules really register


def _real_commands() -> tuple[list[str], dict[str, object]]:
    """Every command the ``roboisf.cli`` modules register, eagerly, in module order."""
    import pkgutil

    import typer
    import typer.main

    import roboisf.cli
    from roboisf.cli.main import COMMANDS

    order = list(dict.fromkeys(e.module for e in COMMANDS))
    registering = {
        m.name
        for m in pkgutil.iter_modules(roboisf.cli.__path__)
        if hasattr(importlib.import_module(f"roboisf.cli.{m.name}"), "register")
    }
    assert registering == set(order), "a cli module with register() is missing from COMMANDS"
    names: list[str] = []
    commands: dict[str, object] = {}
    for module in order:
        app = typer.Typer(rich_markup_mode=None, add_completion=False)
        importlib.import_module(f"roboisf.cli.{module}").register(app)
        group = typer.main.get_group(app)
        names += group.list_commands(None)  # type: ignore[arg-type]
        commands.update(group.commands)
    return names, commands


def test_the_lazy_table_lists_the_real_commands_with_their_help():
    from roboisf.cli.lazy import one_line_help
    from roboisf.cli.main import COMMANDS

    names, commands = _real_commands()
    assert [e.name for e in COMMANDS] == names  # same commands, in module order
    for e in COMMANDS:
        real = commands[e.name]
        assert e.help == one_line_help(real), e.name
        assert not real.hidden  # type: ignore[attr-defined]
        assert type(load_command(e)) is type(real)


def test_root_help_lists_the_table_and_imports_no_command_module():
    # what the user reads: every command with its whole one-line help, no module imported
    code = (
        "import contextlib, io, json, sys\n"
        "from roboisf.cli.main import main\n"
        "buf = io.StringIO()\n"
        "with contextlib.redirect_stdout(buf):\n"
        "    code = main(['--help'])\n"
        "mods = sorted(m for m in sys.modules if m.startswith('roboisf.cli.'))\n"
        "print(json.dumps([code, buf.getvalue(), mods]))\n"
    )
    code_, text, mods = _child(code)  # type: ignore[misc]
    assert code_ == 0
    assert mods == ["roboisf.cli.console", "roboisf.cli.lazy", "roboisf.cli.main"]
    listing = " ".join(text.split("Commands:")[1].split())
    from roboisf.cli.main import COMMANDS

    expected = " ".join(f"{e.name} {e.help}" for e in COMMANDS)
    assert listing == expected


def test_running_a_command_imports_only_its_own_module():
    code = (
        "import contextlib, io, json, sys\n"
        "from roboisf.cli.main import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    code = main(['holder-stiffness', '--help'])\n"
        "mods = sorted(m for m in sys.modules if m.startswith('roboisf.cli.'))\n"
        "print(json.dumps([code, mods]))\n"
    )
    got = _child(code)
    assert got == [
        0,
        [
            "roboisf.cli.console",
            "roboisf.cli.fem",
            "roboisf.cli.lazy",
            "roboisf.cli.main",
            "roboisf.cli.outputs",
        ],
    ]


def test_a_mistyped_command_is_suggested_from_the_lazy_table(capsys):
    from roboisf.cli.main import main

    assert main(["holder-stifness"]) == 2
    assert "Did you mean 'holder-stiffness'" in capsys.readouterr().err


def test_a_stale_table_entry_is_refused():
    from roboisf.cli.lazy import LazyCommand

    with pytest.raises(LookupError, match="adds no command 'nope'"):
        load_command(LazyCommand("nope", "fem", "x"))


def test_sub_groups_list_the_whole_one_line_help(capsys):
    from roboisf.cli.lazy import one_line_help
    from roboisf.cli.main import COMMANDS, main

    _, commands = _real_commands()
    for e in COMMANDS:
        group = commands[e.name]
        subs = getattr(group, "commands", None)
        if not subs:
            continue
        assert main([e.name, "--help"]) == 0
        listing = " ".join(capsys.readouterr().out.split("Commands:")[1].split())
        assert listing == " ".join(f"{n} {one_line_help(c)}" for n, c in subs.items())


def test_help_and_bad_input_do_not_load_rich(tmp_path):
    # typer's rich help renderer (rich.markdown, rich.traceback) is 0.19 s of the 0.3 s budget;
    # help is click's plain formatter, errors go through click's echo, and rich loads with the
    # first message of a command that runs (progress, info)
    runs = [a for a, _ in RUNS if a != ["--version"]]
    out = _child(_CHILD, json.dumps(runs), json.dumps(["rich"]), cwd=tmp_path)
    assert [o["heavy"] for o in out] == [[] for _ in runs]  # type: ignore[union-attr]
    # the guard can fail: a command that runs does print through rich
    out = _child(_CHILD, json.dumps([["part", "cone", "-o", "c.toml"]]), '["rich"]', cwd=tmp_path)
    assert out == [{"code": 0, "heavy": ["rich"]}]


def test_parsing_a_command_loads_no_pydantic(tmp_path):
    # typer 0.29 coerces every non-bool option through a pydantic TypeAdapter: pydantic's import
    # and the adapters cost each command 0.06-0.07 s before its first line runs (0.12-0.13 s
    # against 0.055 s from the console script to analyze's body, 2026-11-29), so pyproject.toml
    # keeps typer below 0.29; this fails if an install brings a typer that does it
    runs = [
        ["analyze", "--help"],
        ["holder-stiffness", "--help"],
        ["part", "cone", "--help"],
        ["analyze"],  # a missing argument: coerced (None) before click reports it
        ["analyze", "no-such-study"],  # a path coerced, then refused
        ["plan", "--study", "no-such-study"],
        ["toolpath", "cone", "-o", "path.csv", "--step-down", "-1"],  # a float coerced
    ]
    out = _child(_CHILD, json.dumps(runs), '["pydantic"]', cwd=tmp_path)
    assert [o["heavy"] for o in out] == [[]] * len(runs)  # type: ignore[union-attr]
    assert [o["code"] for o in out] == [0, 0, 0, 2, 2, 2, 2]  # type: ignore[union-attr]


def test_no_help_text_carries_rich_markup():
    """Help is click's plain text: a rich escape (``\\[mm]``) or tag would be printed literally."""
    import re

    import click

    _, commands = _real_commands()
    bad = re.compile(r"\\\[|\[/?(bold|dim|green|red|yellow|cyan|b|i)\]")

    def texts(cmd: click.Command, path: str) -> list[tuple[str, str]]:
        out = [(path, cmd.help or "")]
        out += [(f"{path} {p.name}", getattr(p, "help", None) or "") for p in cmd.params]
        for name, sub in getattr(cmd, "commands", {}).items():
            out += texts(sub, f"{path} {name}")
        return out

    found = [(w, t) for name, c in commands.items() for w, t in texts(c, name) if bad.search(t)]
    assert len(commands) > 10 and not found, found[:5]


def test_the_console_script_defers_numpys_fortran_wrapper_generator(tmp_path):
    """scipy's vendored array_api_compat runs ``from numpy import *``, which imported
    numpy.f2py (~0.1 s) in every command that loads scipy. The console script defers it
    (cli/lazy.py): the module exists, its code runs only when something reads it — and then
    whole. A library caller's imports are left as they are."""
    plain = (
        "import json, sys, scipy.linalg\n"
        "print(json.dumps('numpy.f2py.crackfortran' in sys.modules))\n"
    )
    if not _child(plain, cwd=tmp_path):  # else the check below would hold without the deferral
        pytest.skip("this scipy and numpy no longer import numpy.f2py: the deferral can go")
    code = (
        "import json, sys\n"
        "from roboisf.cli import main as m\n"
        "calls = []\n"
        "m.main = lambda argv=None: calls.append(1) or 0\n"
        "try:\n"
        "    m.entry()\n"
        "except SystemExit as e:\n"
        "    assert e.code == 0\n"
        "import scipy.linalg, scipy.spatial, numpy\n"
        "out = {'calls': len(calls), 'ran': 'numpy.f2py.crackfortran' in sys.modules}\n"
        "out['usable'] = callable(numpy.f2py.crackfortran.crackfortran)\n"
        "print(json.dumps(out))\n"
    )
    assert _child(code, cwd=tmp_path) == {"calls": 1, "ran": False, "usable": True}


_BLAS = """
import json, os, sys
from roboisf.cli import main as m
m.main = lambda argv=None: 0
try:
    m.entry()
except SystemExit as e:
    assert e.code == 0
import numpy, scipy.linalg  # both OpenBLAS copies (numpy's, scipy's), loaded after the entry
from threadpoolctl import threadpool_info
libs = [i for i in threadpool_info() if i["internal_api"] == "openblas"]
print(json.dumps({"n": len(libs), "threads": sorted({i["num_threads"] for i in libs}),
                  "env": os.environ.get("OPENBLAS_NUM_THREADS")}))
"""


@pytest.mark.parametrize(
    ("given", "threads", "env"),
    [
        ({}, [1], "1"),
        ({"OMP_NUM_THREADS": "2"}, [2], None),
        ({"OPENBLAS_NUM_THREADS": "2"}, [2], "2"),
    ],
)
def test_the_console_script_starts_openblas_on_one_thread_unless_told(
    tmp_path, monkeypatch, given, threads, env
):
    """OpenBLAS starts its pool when loaded and its threads spin ~0.1 s of a core: numpy's and
    scipy's copies each (``perf``: 2.9 % of a paper-cone analyze). The console script leaves
    one thread unless the user's environment chose a number (which is kept)."""
    for v in ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS"):
        monkeypatch.delenv(v, raising=False)
    for k, v in given.items():
        monkeypatch.setenv(k, v)
    out = _child(_BLAS, cwd=tmp_path)
    assert out["n"] >= 1  # else the check below holds for no library
    assert out["threads"] == threads
    assert out["env"] == env
