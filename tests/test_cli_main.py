"""The CLI's conventions: --help everywhere, exit codes, one-line errors."""

import pytest

from roboisf.cli.main import COMMANDS as LISTED
from roboisf.cli.main import app, main

COMMANDS = [
    [],
    ["part"],
    ["toolpath"],
    ["robot"],
    ["scan"],
    ["analyze"],
    ["compensate"],
    ["virtual-cell"],
    ["demo"],
    ["tool-stiffness"],
    ["holder-stiffness"],
    ["plan"],
    ["online"],
    ["study"],
    ["study", "init"],
    ["predict"],
    ["history"],
    ["history", "add"],
    ["history", "list"],
    ["history", "show"],
    ["history", "trend"],
]


@pytest.mark.parametrize("cmd", COMMANDS, ids=lambda c: " ".join(c) or "roboisf")
def test_help_on_every_command(cmd, capsys):
    assert main([*cmd, "--help"]) == 0
    out = capsys.readouterr().out
    assert "Usage" in out and len(out) > 200


def test_usage_errors_exit_2(capsys):
    assert main(["--bogus"]) == 2
    assert main(["analyze"]) == 2  # missing argument
    assert main(["no-such-command"]) == 2
    assert "No such" in capsys.readouterr().err


def test_input_errors_are_one_line_and_exit_2(tmp_path, capsys):
    code = main(["analyze", str(tmp_path / "nowhere"), "-o", str(tmp_path / "out")])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "study.toml" in err and "\n" not in err
    assert not (tmp_path / "out").exists()


def test_version(capsys):
    from roboisf.jit import native

    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    assert "roboisf" in out
    n = len(native.extensions())
    assert n >= 7 and f"C kernels: {n} of {n} built\n" in out  # pip install built them all


def test_every_registered_command_is_covered():
    # the root lists its commands from a lazy table (checked against the modules in
    # test_cli_startup.py) plus any registered on the app itself
    names = {c.name for c in app.registered_commands} | {g.name for g in app.registered_groups}
    names |= {e.name for e in LISTED}
    assert len(names) >= 13
    covered = {c[0] for c in COMMANDS if c}
    assert names <= covered, names - covered


def test_python_dash_m_runs_the_cli():
    """``python -m roboisf`` is the ``roboisf`` command (it once exited 0 and did nothing)."""
    import subprocess
    import sys

    from roboisf import __version__

    out = subprocess.run(
        [sys.executable, "-m", "roboisf", "--version"], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stderr
    assert __version__ in out.stdout
    bad = subprocess.run(
        [sys.executable, "-m", "roboisf", "no-such-command"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 2


def test_a_crash_in_compiled_code_says_where_python_was(tmp_path):
    """The console script enables faulthandler: a segmentation fault in a C kernel (here a
    read of address 0 through ctypes, in place of a command) prints the Python call that
    reached it, not only the shell's "Segmentation fault"."""
    import subprocess
    import sys

    code = (
        "import ctypes, sys\n"
        "import roboisf.cli.main as m\n"
        "def kernel_that_crashes():\n"
        "    return ctypes.string_at(0)\n"
        "m.main = lambda: kernel_that_crashes()\n"
        "sys.argv = ['roboisf', 'analyze']\n"
        "m.entry()\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode != 0
    assert "Segmentation fault" in r.stderr and "kernel_that_crashes" in r.stderr, r.stderr
