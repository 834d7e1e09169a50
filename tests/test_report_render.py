"""The PNGs drawn in worker processes (issue #16): the same bytes as drawn in-process (fork and
spawn), a worker's error or death reaches the caller as one exception before report.html is
written, Ctrl-C stops the workers and leaves no temporary file."""

from __future__ import annotations

import multiprocessing as mp
import os
from pathlib import Path

import pytest

from report_fixtures import make_study
from roboisf.errors import InputError
from roboisf.report import FIGURES, render, write_report
from roboisf.report import document as doc
from roboisf.report import static as st


@pytest.fixture(scope="module")
def study():
    return make_study(n_laps=24, points_per_lap=40)


@pytest.fixture(scope="module")
def in_process(study, tmp_path_factory):
    return write_report(*study, tmp_path_factory.mktemp("serial"), png=True, processes=0).parent


def _same_report(a: Path, b: Path) -> None:
    assert (a / "report.html").read_bytes() == (b / "report.html").read_bytes()
    for fid in FIGURES:
        assert (a / "figures" / f"{fid}.png").read_bytes() == (
            b / "figures" / f"{fid}.png"
        ).read_bytes(), fid
    assert sorted(p.name for p in (b / "figures").iterdir()) == sorted(f"{f}.png" for f in FIGURES)


@pytest.mark.parametrize("processes", [1, 3])
def test_workers_write_the_same_bytes(study, in_process, tmp_path, processes):
    out = write_report(*study, tmp_path, png=True, processes=processes).parent
    _same_report(in_process, out)
    assert not mp.active_children()


def test_spawned_workers_write_the_same_bytes(study, in_process, tmp_path, monkeypatch):
    # the fallback where fork is not available: inputs pickled, figures rebuilt in the worker
    monkeypatch.setattr(render, "_context", lambda: mp.get_context("spawn"))
    out = write_report(*study, tmp_path, png=True, processes=1).parent
    _same_report(in_process, out)


def _no_temporaries(folder: Path) -> None:
    assert not [p.name for p in folder.rglob(".*")], "temporary files left behind"


def test_worker_error_reaches_the_caller(study, tmp_path, monkeypatch):
    parent = os.getpid()
    save = st.save_png

    def failing(fig, path):
        if os.getpid() != parent:  # only in the worker (inherited through fork)
            raise InputError("disk full", file=path)
        return save(fig, path)

    monkeypatch.setattr(st, "save_png", failing)
    (tmp_path / "report.html").write_text("old", encoding="utf-8")
    with pytest.raises(InputError, match="disk full") as err:
        write_report(*study, tmp_path, png=True, processes=1)
    assert any("worker process" in n for n in getattr(err.value, "__notes__", []))
    assert (tmp_path / "report.html").read_text(encoding="utf-8") == "old"
    assert not mp.active_children()
    _no_temporaries(tmp_path)


def test_unpicklable_worker_error_is_named(study, tmp_path, monkeypatch):
    parent = os.getpid()

    class Odd(Exception):  # local class: cannot be pickled
        pass

    def failing(fig, path):
        if os.getpid() != parent:
            raise Odd("no luck")
        return None

    monkeypatch.setattr(st, "save_png", failing)
    with pytest.raises(RuntimeError, match=r"figures/\w+\.png failed in a worker.*Odd: no luck"):
        write_report(*study, tmp_path, png=True, processes=1)


def test_dead_worker_is_reported(study, tmp_path, monkeypatch):
    parent = os.getpid()

    def dying(fig, path):
        if os.getpid() != parent:
            os._exit(3)
        return None

    monkeypatch.setattr(st, "save_png", dying)
    with pytest.raises(RuntimeError, match=r"PNG worker process stopped \(exit codes 3\)"):
        write_report(*study, tmp_path, png=True, processes=1)
    assert not (tmp_path / "report.html").exists()


def test_ctrl_c_stops_the_workers(study, tmp_path, monkeypatch):
    html = doc._figure_html
    calls = []

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:  # workers are drawing by now
            raise KeyboardInterrupt
        return html(*args, **kwargs)

    monkeypatch.setattr(doc, "_figure_html", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_report(*study, tmp_path, png=True, processes=2)
    assert not mp.active_children()
    assert not (tmp_path / "report.html").exists()
    _no_temporaries(tmp_path)


def test_processes_from_the_environment(monkeypatch):
    monkeypatch.setenv(render.PROCESSES_ENV, "0")
    assert render.default_processes() == 0
    monkeypatch.setenv(render.PROCESSES_ENV, "2")
    assert render.default_processes() == 2
    for bad in ("two", "-1"):
        monkeypatch.setenv(render.PROCESSES_ENV, bad)
        with pytest.raises(InputError, match=render.PROCESSES_ENV):
            render.default_processes()
    monkeypatch.delenv(render.PROCESSES_ENV)
    n = render.default_processes()
    assert 0 <= n <= 3 and n == max(0, min(len(os.sched_getaffinity(0)) - 1, 3))
    # no fork (macOS, Windows): no workers unless asked for
    monkeypatch.setattr(render, "_context", lambda: mp.get_context("spawn"))
    assert render.default_processes() == 0
    monkeypatch.setenv(render.PROCESSES_ENV, "1")
    assert render.default_processes() == 1
