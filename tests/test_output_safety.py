"""Outputs never lose a user's data; bad locations are refused before computing; interrupted runs
fail loudly (exit 130/143) and leave the previous results intact (issue 11)."""

import glob
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import typer

from roboisf.cli.main import app, main
from roboisf.errors import InputError
from roboisf.io.atomic import staged_directory
from roboisf.io.outdir import MARKER, STAGING_MARKER, Interrupted, claim_output_dir, read_marker

SRC = Path(__file__).resolve().parents[1] / "src"
VC = ["virtual-cell", "cone", "--scan-points", "20000", "--force-rate", "50"]


def _tree(root: Path) -> dict[str, str]:
    """Every file under ``root`` (hidden ones too) → sha256, relative posix path."""
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_file():
            out[p.relative_to(root).as_posix()] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _no_compute(monkeypatch):
    """Make the virtual cell's simulation fail loudly: a refusal must come before it."""
    import roboisf.virtual.cell as cell

    def boom(*a, **k):
        raise AssertionError("computed before checking the output")

    monkeypatch.setattr(cell, "simulate", boom)


def _err_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("error:"), err
    return err


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    """One small virtual-cell result, copied by the tests that need a previous result."""
    root = tmp_path_factory.mktemp("vc")
    assert main(["-q", *VC, "-o", str(root / "s")]) == 0
    return root / "s"


def _copy(src: Path, dst: Path) -> Path:
    """Copy keeping mtimes (the marker records them)."""
    import shutil

    shutil.copytree(src, dst)
    return dst


# ---------------------------------------------------------------------------------------------
# folders: marker, refusal, --overwrite that keeps user files


def test_marker_lists_exactly_the_files_written(study):
    m = read_marker(study)
    assert m is not None and m["command"] == "virtual-cell"
    listed = {e["path"] for e in m["files"]}
    on_disk = {k for k in _tree(study) if k != MARKER}
    assert listed == on_disk and "truth/truth.json" in listed


def test_non_empty_foreign_folder_is_refused_before_computing(tmp_path, monkeypatch, capsys):
    out = tmp_path / "res"
    (out / "sub").mkdir(parents=True)
    (out / "notes.txt").write_text("my notes")
    (out / "sub" / "thesis.docx").write_bytes(b"\x00thesis")
    before = _tree(tmp_path)
    _no_compute(monkeypatch)
    assert main([*VC, "-o", str(out)]) == 2
    err = _err_line(capsys)
    assert "not empty" in err and "--overwrite" in err and str(out) in err
    assert _tree(tmp_path) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]  # no lock, no staging left


def test_overwrite_keeps_user_files_byte_identical(tmp_path, capsys):
    out = tmp_path / "res"
    (out / "truth").mkdir(parents=True)  # a folder roboisf also writes into
    (out / "notes.txt").write_text("my notes")
    (out / "truth" / "mine.csv").write_text("1,2,3\n")
    (out / "deep" / "er").mkdir(parents=True)
    (out / "deep" / "er" / "x.bin").write_bytes(os.urandom(100))
    user = _tree(out)
    assert main(["-q", *VC, "-o", str(out), "--overwrite"]) == 0
    after = _tree(out)
    assert {k: after[k] for k in user} == user
    listed = {e["path"] for e in read_marker(out)["files"]}
    assert not listed & set(user)  # the marker never claims a user's file
    assert "toolpath.csv" in listed and "truth/truth.json" in listed


def test_same_command_replaces_its_result_and_keeps_user_files(tmp_path, study):
    out = _copy(study, tmp_path / "s")
    (out / "notes.txt").write_text("mine")
    (out / "truth" / "mine.txt").write_text("mine too")
    old = _tree(out)
    assert main(["-q", *VC, "--seed", "3", "-o", str(out)]) == 0
    new = _tree(out)
    assert new["notes.txt"] == old["notes.txt"]
    assert new["truth/mine.txt"] == old["truth/mine.txt"]
    assert new["cnc_scan.ply"] != old["cnc_scan.ply"]  # another seed: really rewritten
    assert set(new) == set(old)
    assert not list(tmp_path.glob(".s.*"))  # no staging, backup or lock left


def test_files_of_the_previous_result_that_the_new_one_lacks_are_removed(tmp_path):
    out = tmp_path / "r"
    with staged_directory(out, "t") as d:
        (d / "a.txt").write_text("1")
        (d / "sub").mkdir()
        (d / "sub" / "b.txt").write_text("2")
        (d / "gone").mkdir()
        (d / "gone" / "c.txt").write_text("3")
    (out / "sub" / "user.txt").write_text("u")
    with staged_directory(out, "t") as d:
        (d / "a.txt").write_text("new")
    assert (out / "a.txt").read_text() == "new"
    assert not (out / "sub" / "b.txt").exists() and not (out / "gone").exists()
    assert (out / "sub" / "user.txt").read_text() == "u"  # keeps its folder too
    assert [e["path"] for e in read_marker(out)["files"]] == ["a.txt"]


def test_other_commands_result_needs_overwrite(tmp_path, study, monkeypatch, capsys):
    out = _copy(study, tmp_path / "s")
    (out / "notes.txt").write_text("mine")
    before = _tree(out)
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "-o", str(out)]) == 2
    assert "`roboisf virtual-cell`" in _err_line(capsys)
    assert _tree(out) == before
    # with --overwrite the old roboisf files go; the user's file stays
    with staged_directory(out, "demo", overwrite=True) as d:
        (d / "index.html").write_text("<html/>")
    assert sorted(_tree(out)) == [MARKER, "index.html", "notes.txt"]
    assert (out / "notes.txt").read_text() == "mine"


def test_a_file_changed_after_roboisf_wrote_it_is_never_replaced(tmp_path, study, capsys):
    out = _copy(study, tmp_path / "s")
    with open(out / "study.toml", "a", encoding="utf-8") as fh:
        fh.write("# my edit\n")
    before = _tree(out)
    for extra in ([], ["--overwrite"]):
        assert main([*VC, "-o", str(out), *extra]) == 2
        assert "study.toml was changed after roboisf wrote it" in _err_line(capsys)
    assert _tree(out) == before


def test_a_new_file_never_lands_on_a_user_file(tmp_path, capsys):
    out = tmp_path / "res"
    out.mkdir()
    (out / "toolpath.csv").write_text("my own toolpath")
    assert main(["-q", *VC, "-o", str(out), "--overwrite"]) == 2
    assert "toolpath.csv exists and roboisf did not write it" in _err_line(capsys)
    assert _tree(out) == {"toolpath.csv": hashlib.sha256(b"my own toolpath").hexdigest()}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


def test_a_forged_marker_cannot_make_roboisf_delete_outside_or_user_files(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("keep")
    out = tmp_path / "r"
    out.mkdir()
    (out / "mine.txt").write_text("keep too")
    (out / "link").symlink_to(victim)
    files = [
        {"path": p, "size": 4, "mtime_ns": victim.stat().st_mtime_ns}
        for p in ("../victim.txt", str(victim), "link", "./link", "sub/../../victim.txt")
    ]
    (out / MARKER).write_text(
        json.dumps({"format": "roboisf-output/1", "command": "t", "files": files})
    )
    with staged_directory(out, "t") as d:
        (d / "new.txt").write_text("n")
    assert victim.read_text() == "keep" and (out / "mine.txt").read_text() == "keep too"
    assert (out / "link").is_symlink()


# ---------------------------------------------------------------------------------------------
# locations refused before any computation


def test_existing_file_where_a_folder_is_expected(tmp_path, monkeypatch, capsys):
    f = tmp_path / "r.txt"
    f.write_text("data")
    _no_compute(monkeypatch)
    assert main([*VC, "-o", str(f)]) == 2
    assert "not a folder" in _err_line(capsys)
    assert f.read_text() == "data"


@pytest.mark.parametrize("where", [".", "cwd", "parent"])
def test_working_folder_and_its_parents_are_refused(tmp_path, monkeypatch, capsys, where):
    work = tmp_path / "w"
    work.mkdir()
    monkeypatch.chdir(work)
    _no_compute(monkeypatch)
    out = {".": ".", "cwd": str(work), "parent": str(tmp_path)}[where]
    assert main([*VC, "-o", out, "--overwrite"]) == 2
    assert "working folder" in _err_line(capsys)
    assert list(work.iterdir()) == []


def test_parent_that_is_a_file(tmp_path, monkeypatch, capsys):
    (tmp_path / "afile").write_text("x")
    _no_compute(monkeypatch)
    assert main([*VC, "-o", str(tmp_path / "afile" / "out")]) == 2
    assert "is a file, not a folder" in _err_line(capsys)


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_unwritable_location(tmp_path, monkeypatch, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        _no_compute(monkeypatch)
        assert main([*VC, "-o", str(ro / "out")]) == 2
        assert "no write permission" in _err_line(capsys)
    finally:
        ro.chmod(0o700)


def test_unwritable_location_by_access_check(tmp_path, monkeypatch, capsys):
    """The same refusal where the test runs as root: the check asks os.access."""
    ro = tmp_path / "ro"
    ro.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, m: False if Path(p) == ro else real(p, m))
    _no_compute(monkeypatch)
    assert main([*VC, "-o", str(ro / "out")]) == 2
    assert "no write permission in " + str(ro) in _err_line(capsys)
    assert list(ro.iterdir()) == []


@pytest.mark.parametrize(
    "rel_out", ["study", "study/results", "."], ids=["equal", "inside", "contains"]
)
def test_analyze_output_never_among_its_inputs(study, tmp_path, monkeypatch, capsys, rel_out):
    import roboisf.decompose.pipeline as pipeline

    root = tmp_path / "proj"
    _copy(study, root / "study")
    before = _tree(root)
    monkeypatch.setattr(pipeline, "analyze", lambda *a, **k: pytest.fail("computed"))
    out = root / rel_out
    assert main(["analyze", str(root / "study"), "-o", str(out), "--overwrite"]) == 2
    err = _err_line(capsys)
    assert "input" in err
    assert _tree(root) == before
    # the study.toml form: its folder is the input
    assert main(["analyze", str(root / "study" / "study.toml"), "-o", str(out)]) == 2
    assert _tree(root) == before


# every command that writes: a refusal before computing, nothing touched
_BUSY = {
    # a study.toml that parses (the command's first check) but is never loaded: the refusal of
    # the output folder comes first
    "analyze": ["analyze", "{s}", "-o", "{o}"],
    "virtual-cell": [*VC, "-o", "{o}"],
    "demo": ["demo", "-o", "{o}"],
    "compensate": ["compensate", "--virtual", "cone", "-o", "{o}"],
    "plan": ["plan", "--part", "{d}/p.toml", "-o", "{o}"],
}
_FILES = {
    "part": ["part", "cone", "-o", "{o}.toml"],
    "toolpath": ["toolpath", "cone", "-o", "{o}.csv"],
    "toolpath --part": ["toolpath", "--part", "{d}/p.toml", "-o", "{o}.csv"],
    "toolpath krl .dat": ["toolpath", "cone", "-o", "{o}.src"],
    "tool-stiffness": [
        "tool-stiffness",
        "--ball-diameter",
        "10",
        "--length",
        "66",
        "-o",
        "{o}.json",
    ],
    "holder-stiffness": ["holder-stiffness", "--section", "50:40", "-o", "{o}.json"],
    "robot show": ["robot", "show", "-o", "{o}.png"],
    "robot identify": ["robot", "identify", "{d}/calib.csv", "-o", "{o}.toml"],
    "robot deflect": [
        "robot",
        "deflect",
        "--toolpath",
        "{d}/t.csv",
        "--forces",
        "{d}/f.csv",
        "-o",
        "{o}.csv",
    ],
    "scan compare": ["scan", "compare", "{d}/s.ply", "--part", "{d}/p.toml", "-o", "{o}.csv"],
    "online": ["online", "-c", "egm", "--virtual", "cone", "-o", "{o}.parquet"],
}


@pytest.mark.parametrize("cmd", list(_BUSY), ids=list(_BUSY))
def test_every_folder_command_refuses_a_foreign_folder(
    cmd, tmp_path, tmp_path_factory, monkeypatch, capsys
):
    out = tmp_path / "out"
    out.mkdir()
    (out / "thesis.docx").write_bytes(b"precious")
    study = tmp_path_factory.mktemp("study")
    (study / "study.toml").write_text("[study]\n")
    monkeypatch.chdir(tmp_path)
    argv = [a.format(d=tmp_path, o=out, s=study) for a in _BUSY[cmd]]
    assert main(argv) == 2
    assert "not empty" in _err_line(capsys)
    assert _tree(tmp_path) == {"out/thesis.docx": hashlib.sha256(b"precious").hexdigest()}


@pytest.mark.parametrize("cmd", list(_FILES), ids=list(_FILES))
def test_every_file_command_refuses_an_existing_file(cmd, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv = [a.format(d=tmp_path, o=tmp_path / "out") for a in _FILES[cmd]]
    target = Path(argv[argv.index("-o") + 1])
    if cmd == "toolpath krl .dat":
        target = target.with_suffix(".dat")  # the .src is new, its .dat is not
    target.write_text("mine")
    assert main(argv) == 2
    assert "exists; pass --overwrite" in _err_line(capsys)
    assert _tree(tmp_path) == {target.name: hashlib.sha256(b"mine").hexdigest()}
    # a folder where the file should go
    target.unlink()
    target.mkdir()
    assert main(argv) == 2
    assert "is a folder" in _err_line(capsys)


def test_file_output_overwrite(tmp_path, capsys):
    out = tmp_path / "cone.toml"
    assert main(["-q", "part", "cone", "-o", str(out)]) == 0
    first = out.read_text()
    assert main(["part", "cone", "--depth", "50", "-o", str(out)]) == 2
    assert out.read_text() == first
    assert main(["-q", "part", "cone", "--depth", "50", "-o", str(out), "--overwrite"]) == 0
    assert out.read_text() != first
    assert main(["part", "cone", "-o", str(out), "--overwrite"]) == 0  # not an input: fine
    capsys.readouterr()
    prof = tmp_path / "p.csv"
    prof.write_text("r,z\n40,0\n20,-20\n")
    assert main(["part", "profile", str(prof), "-o", str(tmp_path / "p.toml")]) == 0


# ---------------------------------------------------------------------------------------------
# lock and stale staging


def test_second_run_into_a_locked_output_exits_2_naming_the_holder(tmp_path, capsys):
    out = tmp_path / "s"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from roboisf.io.outdir import claim_output_dir; "
            f"claim_output_dir({str(out)!r}, 'virtual-cell'); print('held', flush=True); "
            "time.sleep(60)",
        ],
        env={**os.environ, "PYTHONPATH": str(SRC)},
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        t0 = time.monotonic()
        assert main([*VC, "-o", str(out)]) == 2
        assert time.monotonic() - t0 < 5  # at once, not after computing
        err = _err_line(capsys)
        assert "another roboisf run" in err and f"pid {holder.pid}" in err
        assert not out.exists()
    finally:
        holder.kill()
        holder.wait()
    # the kernel dropped the dead holder's lock: the lock file is stale and taken over
    assert (tmp_path / ".s.roboisf-lock").exists()
    assert main(["-q", *VC, "-o", str(out)]) == 0
    assert not (tmp_path / ".s.roboisf-lock").exists()


def test_lock_refuses_a_second_claim_and_is_released(tmp_path):
    from roboisf.io import outdir

    with outdir.output_session():
        claim_output_dir(tmp_path / "x", "t")
        assert (tmp_path / ".x.roboisf-lock").read_text().startswith(f"pid {os.getpid()} ")
        # another claim (as another run would make it; flock is per open file)
        with pytest.raises(InputError, match=f"another roboisf run .*pid {os.getpid()}"):
            outdir._claim_dir(tmp_path / "x", "x", "t", False, ())
    assert not (tmp_path / ".x.roboisf-lock").exists()


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_stale_staging_of_dead_runs_is_cleaned_only_when_ours(tmp_path):
    def stage(name: str, pid: int | None, output: str = "s") -> Path:
        d = tmp_path / name
        d.mkdir()
        (d / "big.bin").write_bytes(b"x" * 1000)
        if pid is not None:
            (d / STAGING_MARKER).write_text(
                json.dumps({"format": "roboisf-output/1", "pid": pid, "output": output})
            )
        return d

    dead = _dead_pid()
    gone = [stage(".s.staging.abc", dead), stage(".s.old.def", dead)]
    kept = [
        stage(".s.staging.nomarker", None),  # not provably ours
        stage(".s.staging.alive", os.getppid()),  # a live process
        stage(".s.staging.other", dead, output="t"),  # marker of another output
        stage(".t.staging.x", dead, output="t"),  # another output's name
        stage("s.staging.y", dead),  # not our naming
    ]
    assert main(["-q", *VC, "-o", str(tmp_path / "s")]) == 0
    assert not any(d.exists() for d in gone)
    assert all((d / "big.bin").exists() for d in kept)


# ---------------------------------------------------------------------------------------------
# exit codes, signals, echoed values


def test_typer_exit_code_is_returned(capsys):
    @app.command("boom-exit-4")
    def _boom() -> None:
        raise typer.Exit(4)

    try:
        assert main(["boom-exit-4"]) == 4
    finally:
        app.registered_commands.pop()


@pytest.mark.parametrize(
    ("exc", "code"),
    [
        (KeyboardInterrupt, 130),
        (Interrupted(signal.SIGINT), 130),
        (Interrupted(signal.SIGTERM), 143),
        (Interrupted(signal.SIGHUP), 129),
    ],
    ids=["KeyboardInterrupt", "SIGINT", "SIGTERM", "SIGHUP"],
)
def test_interrupt_in_process_exits_non_zero_and_removes_staging(
    tmp_path, study, monkeypatch, capsys, exc, code
):
    import roboisf.virtual.cell as cell

    out = _copy(study, tmp_path / "s")
    before = _tree(out)

    def interrupted(*a, **k):
        assert glob.glob(str(tmp_path / ".s.staging.*"))
        raise exc

    monkeypatch.setattr(cell, "write_force_log", interrupted)
    assert main(["-q", *VC, "-o", str(out)]) == code
    err = capsys.readouterr().err.strip()
    assert "\n" not in err, err
    assert err.startswith(_SAID[code])
    assert f"nothing written to {out} (its previous contents are intact)" in err
    assert _tree(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]


#: exit code → how the one line on stderr begins
_SAID = {130: "interrupted (SIGINT)", 143: "terminated (SIGTERM)", 129: "hung up (SIGHUP"}


@pytest.mark.parametrize(
    "sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["SIGINT", "SIGTERM", "SIGHUP"]
)
def test_signal_exits_128_plus_n_and_leaves_previous_results(tmp_path, study, sig):
    out = _copy(study, tmp_path / "s")
    before = _tree(out)
    # the signal lands while the study is being written (~1 s of staging: force and joint logs);
    # polling every 5 ms for the staging folder also hits the moment right after it is created
    argv = [*VC, "-o", str(out)]
    p = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"from roboisf.cli.main import main; raise SystemExit(main({argv!r}))",
        ],
        env={**os.environ, "PYTHONPATH": str(SRC)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 300
    while not glob.glob(str(tmp_path / ".s.staging.*")):
        assert p.poll() is None, p.communicate()[1]
        assert time.monotonic() < deadline
        time.sleep(0.005)
    p.send_signal(sig)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 128 + sig, err
    last = err.strip().splitlines()[-1]
    assert last.startswith(_SAID[128 + sig]), err
    assert f"nothing written to {out} (its previous contents are intact)" in last
    assert "Traceback" not in err
    assert sorted(q.name for q in tmp_path.iterdir()) == ["s"]  # no staging, no lock
    assert _tree(out) == before


@pytest.mark.parametrize("value", [":x:", "[red]boom[/red]", ":thumbs_up: [bold]x"])
def test_echoed_values_are_never_markup_or_emoji(value, tmp_path, capsys, monkeypatch):
    assert main(["virtual-cell", value, "-o", str(tmp_path / "o")]) == 2
    assert repr(value) in _err_line(capsys)
    # an info line carrying a user path
    out = tmp_path / value.replace("/", "_")
    assert main(["part", "cone", "-o", f"{out}.toml"]) == 0
    assert f"wrote {out}.toml" in capsys.readouterr().out
    # a warning carrying a user value
    from roboisf.cli.console import state

    state.warn(value)
    assert value in capsys.readouterr().err


def test_lock_without_flock_takes_over_a_dead_pid_and_refuses_a_live_one(tmp_path, monkeypatch):
    """The O_EXCL fallback (no fcntl, or a file system without flock)."""
    from roboisf.io import outdir

    monkeypatch.setattr(
        outdir._Lock, "_acquire", classmethod(lambda cls, o, s, c: cls._acquire_excl(o, s, c))
    )
    lock = tmp_path / ".x.roboisf-lock"
    lock.write_text(f"pid {_dead_pid()} roboisf plan\n")
    claim = outdir._claim_dir(tmp_path / "x", "x", "t", False, ())
    assert lock.read_text().startswith(f"pid {os.getpid()} ")
    with pytest.raises(InputError, match=f"another roboisf run .*pid {os.getpid()}"):
        outdir._claim_dir(tmp_path / "x", "x", "t", False, ())
    claim.release()
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    lock.write_text(f"pid {os.getppid()} roboisf plan\n")  # alive: never taken over
    with pytest.raises(InputError, match=f"pid {os.getppid()}"):
        outdir._claim_dir(tmp_path / "x", "x", "t", False, ())
    assert lock.read_text() == f"pid {os.getppid()} roboisf plan\n"


def test_a_failed_run_leaves_no_empty_parent_folders(tmp_path, capsys):
    study = tmp_path / "st"
    study.mkdir()
    (study / "study.toml").write_text("[nonsense]\n")  # parses as TOML; load_study refuses it
    argv = ["analyze", str(study), "-o", str(tmp_path / "a" / "b" / "out")]
    assert main(argv) == 2  # fails after the output was claimed
    assert "[nonsense]: unknown table" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["st"]
    out = tmp_path / "c" / "d.toml"
    assert main(["-q", "part", "cone", "-o", str(out)]) == 0
    assert out.is_file()  # a written output keeps the folders made for it
