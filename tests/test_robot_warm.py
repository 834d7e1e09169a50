"""The background build of the compiled robot kernels (issue #31): a first run on an empty
kernel cache is served by the numpy engine while one detached process builds the kernels; a
later process finds the cache and runs compiled."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from roboisf.robot import warm
from roboisf.robot.vjm_kernel import HAVE_NUMBA

needs_numba = pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed")


def test_switched_off_means_ready(monkeypatch):
    monkeypatch.setenv(warm.ENV, "0")
    monkeypatch.setattr(warm, "all_cached", lambda: False)
    monkeypatch.setattr(warm, "_spawn", lambda: pytest.fail("no builder when switched off"))
    assert warm.compiled_ready()


def test_cold_cache_starts_one_builder_per_process(monkeypatch):
    monkeypatch.setenv(warm.ENV, "1")
    monkeypatch.setattr(warm, "_started", False)
    monkeypatch.setattr(warm, "all_cached", lambda: False)
    spawned: list[int] = []
    monkeypatch.setattr(warm, "_spawn", lambda: spawned.append(1))
    assert not warm.compiled_ready()
    assert not warm.compiled_ready()
    assert spawned == [1]
    monkeypatch.setattr(warm, "all_cached", lambda: True)
    assert warm.compiled_ready()


def test_lock_is_exclusive_and_a_stale_one_is_taken_over(tmp_path):
    lock = tmp_path / "b.lock"
    assert warm._take_lock(lock)
    assert not warm._take_lock(lock)  # a second builder (another process, an xdist worker)
    old = time.time() - warm.STALE_S - 10
    os.utime(lock, (old, old))  # left by a killed builder
    assert warm._take_lock(lock)


def test_no_writable_temp_folder_means_no_builder_and_no_error(tmp_path, monkeypatch):
    monkeypatch.setattr(warm.tempfile, "gettempdir", lambda: str(tmp_path / "missing"))
    monkeypatch.setattr(
        warm.subprocess, "Popen", lambda *a, **k: pytest.fail("no builder without a lock")
    )
    warm._spawn()


def test_lock_depends_on_the_cache_folder(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "a"))
    a = warm.lock_path()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "b"))
    assert warm.lock_path() != a


_PROBE = """
import json, sys
import numpy as np
from roboisf.robot import warm, vjm_kernel
from roboisf.robot.presets import list_robots, load_robot
m = next(m for m in map(load_robot, list_robots()) if m.stiffness is not None)
rng = np.random.default_rng(3)
mid = 0.5 * (m.q_min + m.q_max)
q = mid + rng.uniform(-0.3, 0.3, (500, 6)) * (m.q_max - m.q_min) / 2
W = rng.normal(0, 300, (500, 6))
compiled = vjm_kernel.use_numba("auto")
d = m.deflection(q, W)  # backend "auto"
np.save(sys.argv[1], d)
print(json.dumps({"compiled": compiled, "lock": str(warm.lock_path())}))
"""


@needs_numba
@pytest.mark.slow
def test_first_process_serves_numpy_builds_in_background_next_runs_compiled(tmp_path):
    import json

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), **{warm.ENV: "1"})
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    run = [sys.executable, "-c", _PROBE]
    first = json.loads(
        subprocess.run(
            [*run, str(tmp_path / "d1.npy")], env=env, check=True, capture_output=True, text=True
        ).stdout
    )
    assert first["compiled"] is False  # empty cache: numpy serves the first run
    lock = Path(first["lock"])
    deadline = time.time() + 600
    while lock.exists() and time.time() < deadline:  # the builder removes its lock when done
        time.sleep(1.0)
    assert not lock.exists(), "background build did not finish in 10 min"
    second = json.loads(
        subprocess.run(
            [*run, str(tmp_path / "d2.npy")], env=env, check=True, capture_output=True, text=True
        ).stdout
    )
    assert second["compiled"] is True  # the cache the builder left is used
    d1, d2 = np.load(tmp_path / "d1.npy"), np.load(tmp_path / "d2.npy")
    # numpy vs numba engine: same arithmetic up to rounding (tests/test_robot_vjm.py: ≤ 1e-14
    # relative on compliances); deflections here are ≤ 1e-3 m, so 1e-15 m absolute ≈ 1e-12 rel.
    np.testing.assert_allclose(d2, d1, rtol=1e-10, atol=1e-15)


def test_spawning_a_builder_says_so_once(monkeypatch, tmp_path):
    from roboisf import progress

    said: list[str] = []
    progress.set_notice(said.append)
    try:
        monkeypatch.setattr(warm, "lock_path", lambda: tmp_path / "x.lock")
        monkeypatch.setattr(warm.subprocess, "Popen", lambda *a, **k: None)
        warm._spawn()
        (tmp_path / "x.lock").unlink()
        warm._spawn()
    finally:
        progress.set_notice(None)
    assert len(said) == 1 and "background" in said[0] and warm.BUILD_WAIT in said[0]


def test_builder_is_detached_silent_and_does_not_spawn_builders(monkeypatch, tmp_path):
    """Its own session (a Ctrl-C of the user's command does not reach it), stdio on /dev/null
    (never writes to the user's terminal), background building off in its environment."""
    seen: dict = {}
    monkeypatch.setattr(warm, "lock_path", lambda: tmp_path / "y.lock")
    monkeypatch.setattr(warm.subprocess, "Popen", lambda cmd, **k: seen.update(cmd=cmd, **k))
    warm._spawn()
    assert seen["start_new_session"] is True
    assert all(seen[s] is subprocess.DEVNULL for s in ("stdin", "stdout", "stderr"))
    assert seen["env"][warm.ENV] == "0"
    assert seen["cmd"][1:3] == ["-m", "roboisf.robot.warm"]
    assert seen["cmd"][3] == str(tmp_path / "y.lock")  # the builder removes the lock when done


def test_builder_removes_its_lock_even_when_the_build_fails(monkeypatch, tmp_path):
    lock = tmp_path / "z.lock"
    lock.write_text("1")
    monkeypatch.setattr(warm, "build", lambda: 1 / 0)
    assert warm.main([str(lock)]) == 1
    assert not lock.exists()
