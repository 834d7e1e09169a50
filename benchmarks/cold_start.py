"""First call vs second call of every heavy command from a fresh kernel cache (issue #31).

Run by hand:  PYTHONPATH=src python benchmarks/cold_start.py [--only demo,analyze] [--wait 600]
              [--no-numba]

For each command — ``demo``, ``analyze`` of a small virtual study, ``robot show``, ``plan``,
``online --simulate`` — a fresh, empty ``NUMBA_CACHE_DIR`` (what a new install has), then:
the **first** call (timed), a wait until any background kernel builder it started has finished
(its lock file in the temp folder is gone; the wait is printed, it is not the user's), then the
**second** call (timed), back to back so that both see the same machine load. Printed side by
side: first, second, first/second (the issue's target: ≤ 1.5), the builder wait, and the load
average before the pair. The inputs (a cone part, the small virtual study) are made once up
front with their own cache and are not timed. ``ROBOISF_BACKGROUND_COMPILE=0`` in the
environment measures the old behaviour (compile in the foreground on first use); ``--no-numba``
runs the timed commands with numba and the C kernels switched off: the numpy engines throughout
(``ROBOISF_NUMBA=0 ROBOISF_NATIVE=0``, inherited by the demo's worker processes).

``--install`` measures what a new user gets: a new venv, ``pip install -e`` of a clean copy of
this tree (timed: it builds the kernels, setup.py's ``build_kernels``), then every command's
first and second call with that venv's Python and numba's cache as the install left it (no
``NUMBA_CACHE_DIR``; a private temp folder, where a background builder's lock would show).

The machine is usually shared: ratios from back-to-back pairs hold up under load, absolute
times need a quiet machine.
"""

from __future__ import annotations

import argparse
import compileall
import os
import shutil
import subprocess
import sys
import tempfile
import time

from machine import speed_line  # benchmarks/machine.py (this folder is on sys.path)

RUN = (
    "import sys; from roboisf.cli.main import entry; sys.argv = ['roboisf', *sys.argv[1:]]; entry()"
)


def cases(d: str) -> dict[str, list[str]]:
    """Command name → arguments; ``{o}`` is replaced by a fresh output folder per call."""
    return {
        "demo": ["demo", "-o", "{o}"],
        "analyze (small virtual study)": ["analyze", f"{d}/small", "-o", "{o}"],
        "robot show": ["robot", "show", "--robot", "irb7600-500-2.55", "-o", "{o}/map.png"],
        "plan": ["plan", "--part", f"{d}/cone.toml", "-o", "{o}"],
        "online --simulate": [
            "online",
            "-c",
            "egm",
            "--virtual",
            "cone",
            "--simulate",
            "--duration",
            "5",
            "-o",
            "{o}/sim.parquet",
        ],
    }


def _run(
    args: list[str], env: dict[str, str], cwd: str, python: str = sys.executable
) -> tuple[float, int]:
    t = time.perf_counter()
    r = subprocess.run(
        [python, "-c", RUN, "-q", *args],
        env=env,
        cwd=cwd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    if r.returncode != 0:
        print(f"  ! {' '.join(args)} → exit {r.returncode}: {r.stderr.strip()[-300:]}", flush=True)
    return time.perf_counter() - t, r.returncode


def _lock(cache: str) -> str:
    """The lock file of the background builder for kernel cache ``cache`` (it exists while that
    builder runs): only this benchmark's builders are waited for, not other users'."""
    from roboisf.jit.background import lock_path

    old = os.environ.get("NUMBA_CACHE_DIR")
    os.environ["NUMBA_CACHE_DIR"] = cache
    try:
        return str(lock_path())
    finally:
        if old is None:
            del os.environ["NUMBA_CACHE_DIR"]
        else:
            os.environ["NUMBA_CACHE_DIR"] = old


def _wait_builder(cache: str | None, timeout: float, tmp: str | None = None) -> float:
    """Wait while the builder for kernel cache ``cache`` runs — or, ``tmp`` given, while any
    builder's lock is in that temp folder (an installed copy's lock has another key)."""
    t = time.perf_counter()

    def building() -> bool:
        if tmp is not None:
            return any(n.startswith("roboisf-kernel-build-") for n in os.listdir(tmp))
        assert cache is not None
        return os.path.exists(_lock(cache))

    while building() and time.perf_counter() - t < timeout:
        time.sleep(0.5)
    return time.perf_counter() - t


def _install(d: str) -> tuple[str, float]:
    """A new venv in ``d`` with a clean copy of this tree installed as the README does
    (``pip install -e``); its Python and the install's wall time [s]."""
    root = os.path.abspath(os.path.join(os.path.dirname(__file__), os.pardir))
    files = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard"],
        cwd=root,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    proj = os.path.join(d, "proj")
    for f in files:
        if os.path.isfile(os.path.join(root, f)):
            os.makedirs(os.path.dirname(os.path.join(proj, f)), exist_ok=True)
            shutil.copy2(os.path.join(root, f), os.path.join(proj, f))
    venv = os.path.join(d, "venv")
    subprocess.run([sys.executable, "-m", "venv", venv], check=True)
    python = os.path.join(venv, "bin", "python")
    t = time.perf_counter()
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    subprocess.run(
        [python, "-m", "pip", "install", "-q", "-e", proj],
        check=True,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    return python, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", help="comma-separated case names (prefixes) to run")
    ap.add_argument("--wait", type=float, default=600.0, help="longest wait for a builder [s]")
    ap.add_argument(
        "--no-numba",
        action="store_true",
        help="run the timed commands without numba (plain install)",
    )
    ap.add_argument(
        "--install",
        action="store_true",
        help="a new venv and `pip install -e` of this tree first (timed); its cache, as installed",
    )
    a = ap.parse_args()

    base = dict(os.environ)
    here = os.path.abspath(os.path.join(os.path.dirname(__file__), os.pardir, "src"))
    base["PYTHONPATH"] = here + os.pathsep + base.get("PYTHONPATH", "")
    sys.path.insert(0, here)  # roboisf.jit of this tree, for the builders' lock files
    # Python's bytecode of this tree, as pip compiles it at install: with PYTHONDONTWRITEBYTECODE
    # set (some shells and CI images) or stale .pyc files, every call would compile the modules
    # edited since from source, first and second alike (0.3–0.5 s of a warm analyze, 2026-11-29)
    compileall.compile_dir(os.path.join(here, "roboisf"), quiet=1)
    print(
        "bytecode: roboisf compiled up front (as pip does at install); "
        f"PYTHONDONTWRITEBYTECODE={os.environ.get('PYTHONDONTWRITEBYTECODE', '')!r}"
    )
    with tempfile.TemporaryDirectory(prefix="roboisf-cold-") as d:
        setup = dict(base, NUMBA_CACHE_DIR=os.path.join(d, "setup-cache"))
        python, tmp = sys.executable, None
        print(speed_line(), flush=True)  # the machine's pace now (benchmarks/machine.py)
        if a.install:
            python, took = _install(d)
            tmp = os.path.join(d, "tmp")
            os.makedirs(tmp)
            # as a user's shell: bytecode written on first import (pip does not compile an
            # editable install's sources: the first call pays that, and it is timed)
            drop = ("NUMBA_CACHE_DIR", "PYTHONPATH", "PYTHONDONTWRITEBYTECODE")
            base = {k: v for k, v in os.environ.items() if k not in drop}
            base["TMPDIR"] = tmp
            print(f"pip install -e (new venv, kernels built at install): {took:.1f} s", flush=True)
        print("inputs (not timed) …", flush=True)
        for args in (
            ["part", "cone", "-o", f"{d}/cone.toml"],
            [
                "virtual-cell",
                "cone",
                "--step-down",
                "2",
                "--spacing",
                "4",
                "--scan-points",
                "150000",
                "--force-rate",
                "50",
                "--joint-rate",
                "20",
                "-o",
                f"{d}/small",
            ],
        ):
            # with this tree (not the new install: its bytecode and kernels stay unused)
            if _run(args, setup, d)[1] != 0:
                sys.exit("could not make the inputs")
        _wait_builder(setup["NUMBA_CACHE_DIR"], a.wait)
        print(
            f"background build: {os.environ.get('ROBOISF_BACKGROUND_COMPILE', '1') != '0'}; "
            "compiled kernels: "
            + ("off, ROBOISF_NUMBA=0 ROBOISF_NATIVE=0 (plain install)" if a.no_numba else "on")
        )
        print(
            f"{'command':32s} {'first s':>8s} {'second s':>9s} {'ratio':>6s} "
            f"{'builder s':>9s}  load (1/5/15 min)"
        )
        for k, (name, args) in enumerate(cases(d).items()):
            if a.only and not any(name.startswith(p) for p in a.only.split(",")):
                continue
            env = dict(base)
            if not a.install:
                env["NUMBA_CACHE_DIR"] = os.path.join(d, f"cache-{k}")
            if a.no_numba:  # the plain install: neither numba nor the C forms
                env["ROBOISF_NUMBA"] = "0"
                env["ROBOISF_NATIVE"] = "0"
            load = " ".join(f"{x:.2f}" for x in os.getloadavg())
            times = []
            waited = 0.0
            for call in range(2):
                out = os.path.join(d, f"out-{k}-{call}")
                t, _ = _run([x.replace("{o}", out) for x in args], env, d, python)
                times.append(t)
                shutil.rmtree(out, ignore_errors=True)
                if call == 0:
                    waited = _wait_builder(env.get("NUMBA_CACHE_DIR"), a.wait, tmp)
            print(
                f"{name:32s} {times[0]:8.1f} {times[1]:9.1f} {times[0] / times[1]:6.2f} "
                f"{waited:9.1f}  {load}",
                flush=True,
            )
    print("ratios are from back-to-back pairs; absolute times need a quiet machine")


if __name__ == "__main__":
    main()
