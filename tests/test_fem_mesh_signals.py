"""gmsh's initialisation resets SIGPIPE to its default action (terminate the process); Python
ignores SIGPIPE so that writing to a pipe whose reader is gone raises BrokenPipeError. Found as
an xdist worker dying with exit 141 in test_demo_error_stops_the_second_process, after an earlier
test in the same worker had meshed with gmsh: the demo stopped its second process while a queue
thread still wrote to it. Each case runs in a fresh interpreter (gmsh's state is per process)."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGPIPE"), reason="no SIGPIPE here")

_WRITE_TO_A_CLOSED_PIPE = """
import os
r, w = os.pipe()
os.close(r)
try:
    os.write(w, b"x")
except BrokenPipeError:
    print("BrokenPipeError")
"""


def _run(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code) + _WRITE_TO_A_CLOSED_PIPE],
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize("where", ["main thread", "worker thread"])
def test_a_broken_pipe_is_an_exception_after_gmsh(where):
    body = "with gmsh_session():\n    pass\n"
    if where == "worker thread":
        body = (
            "import threading\n"
            "def run():\n" + textwrap.indent(body, "    ") + "t = threading.Thread(target=run)\n"
            "t.start(); t.join()\n"
        )
    p = _run("from roboisf.fem.mesh import gmsh_session\n" + body)
    assert p.returncode == 0, (p.returncode, p.stderr)  # −13: killed by SIGPIPE
    assert p.stdout.strip() == "BrokenPipeError"


def test_gmsh_itself_still_resets_it():
    """The negative control: plain gmsh.initialize kills the writer (if a gmsh release stops
    doing it, the restore is moot, not wrong)."""
    p = _run(
        "import gmsh\n"
        "gmsh.initialize(['-noenv'], readConfigFiles=False, run=False, interruptible=False)\n"
    )
    assert p.returncode == -signal.SIGPIPE and p.stdout == ""  # killed by the signal
