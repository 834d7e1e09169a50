"""Whether a process still runs, for the tests that kill a command and look for what it left
(tests/test_online_rt.py, tests/test_demo.py). Linux: reads ``/proc``."""

from __future__ import annotations


def running(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie — ended, not yet reaped by init — does not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False
