"""Every failure a clean one (issue 29): what the machine refuses (a full disk, a name too long,
no permission), absurd magnitudes, results of another study — one line on stderr, exit 2, no
traceback, no lock or staging file left, no user file changed."""

from __future__ import annotations

import errno
import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from roboisf.cli.main import main
from roboisf.errors import ResourceError
from roboisf.io import outdir
from roboisf.io.atomic import staged_directory
from roboisf.io.outdir import claim_output_file, environment_error, output_session

SRC = Path(__file__).resolve().parents[1] / "src"


def _tree(root: Path) -> dict[str, str]:
    """Every file under ``root`` (hidden ones too) → sha256, relative posix path."""
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def _err_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("error:"), err
    assert "Traceback" not in err
    return err


# -- environment errors ------------------------------------------------------------------------


def test_environment_error_names_the_path_and_what_to_do():
    e = environment_error(OSError(errno.ENOSPC, "No space left on device", "/data/r.csv"))
    assert isinstance(e, ResourceError)
    assert str(e).startswith("/data/r.csv: no space left on device; free space")
    e = environment_error(OSError(errno.ENAMETOOLONG, "File name too long", "x" * 300))
    assert "shorter name" in str(e) and len(str(e)) < 300  # the long name is shortened
    import socket

    e = environment_error(socket.gaierror(-2, "Name or service not known"), "netft:256.1.1.1")
    assert str(e).startswith("netft:256.1.1.1: the host name cannot be resolved")
    assert "check the address" in str(e)
    assert "not enough memory" in str(environment_error(MemoryError()))


def test_an_error_without_a_path_names_the_claimed_output(tmp_path):
    with output_session():
        claim_output_file(tmp_path / "t.csv", "toolpath")
        e = environment_error(OSError(errno.ENOSPC, "No space left on device"))
    assert str(e).startswith(f"{tmp_path / 't.csv'}: no space left on device")
    assert f"nothing written to {tmp_path / 't.csv'}" in str(e)


def test_a_lock_the_full_disk_refuses_is_removed(tmp_path, monkeypatch, capsys):
    # the lock file is created (a directory entry), its content is not (ENOSPC): before, a 0-byte
    # lock was left behind and the OSError ended in a traceback
    def full(fd, n):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(outdir.os, "ftruncate", full)
    (tmp_path / "p.toml").write_text("mine")
    assert main(["part", "cone", "-o", str(tmp_path / "new.toml")]) == 2
    err = _err_line(capsys)
    assert "new.toml: no space left on device; free space" in err
    assert _tree(tmp_path) == {"p.toml": hashlib.sha256(b"mine").hexdigest()}
    assert sorted(os.listdir(tmp_path)) == ["p.toml"]


def test_a_staging_folder_whose_marker_the_disk_refuses_is_removed(tmp_path, monkeypatch):
    real = Path.write_text

    def full(self, *a, **k):
        if self.name == outdir.STAGING_MARKER:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, *a, **k)

    monkeypatch.setattr(Path, "write_text", full)
    with output_session(), pytest.raises(OSError), staged_directory(tmp_path / "vc", "x"):
        pytest.fail("the staging folder cannot exist without its marker")
    assert os.listdir(tmp_path) == []  # no .vc.staging.*, no lock


# every command that writes, in a child process whose files may not grow past 64 bytes
# (RLIMIT_FSIZE: the kernel refuses the write with EFBIG, as a full disk refuses with ENOSPC)
_LIMITED = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (64, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
from roboisf.cli.main import main
sys.exit(main(sys.argv[1:]))
"""

_WRITERS = {
    "part": ["part", "cone", "-o", "{o}/p.toml"],
    "toolpath": ["toolpath", "cone", "--step-down", "2", "-o", "{o}/t.csv"],
    "toolpath krl": [
        "toolpath",
        "cone",
        "--step-down",
        "2",
        "--placement",
        "base",
        "--tool",
        "300",
        "-o",
        "{o}/t.src",
    ],
    "holder-stiffness": ["holder-stiffness", "--section", "50:40", "-o", "{o}/h.json"],
    "virtual-cell": [
        "virtual-cell",
        "cone",
        "--scan-points",
        "2000",
        "--step-down",
        "2",
        "--spacing",
        "4",
        "-o",
        "{o}/vc",
    ],
}


@pytest.mark.parametrize("cmd", list(_WRITERS), ids=list(_WRITERS))
def test_every_writer_on_a_disk_that_refuses_exits_2_and_leaves_nothing(cmd, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("precious")  # under the limit: written before the child runs
    before = _tree(tmp_path)
    argv = [a.format(o=out) for a in _WRITERS[cmd]]
    env = {**os.environ, "PYTHONPATH": str(SRC), "NO_COLOR": "1"}
    r = subprocess.run(
        [sys.executable, "-c", _LIMITED, "-q", *argv],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert r.returncode == 2, r.stderr
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:"), r.stderr
    assert "larger than the file system or a size limit" in err[0]
    assert "nothing written to" in err[0]
    assert _tree(tmp_path) == before
    assert sorted(os.listdir(out)) == ["mine.txt"]  # no lock, no staging, no temporary file


@pytest.mark.parametrize("kind", ["file", "folder"])
def test_an_output_name_too_long_for_the_file_system_is_refused_first(kind, tmp_path, capsys):
    name = "r" * 240  # the file system takes it, not with roboisf's lock and staging suffixes
    if kind == "file":
        argv = ["part", "cone", "-o", str(tmp_path / f"{name}.toml")]
    else:
        argv = ["virtual-cell", "cone", "-o", str(tmp_path / name)]
    assert main(argv) == 2
    err = _err_line(capsys)
    assert "bytes long; the file system allows 255 per name" in err
    assert "choose a shorter name" in err
    assert os.listdir(tmp_path) == []


def test_a_missing_folder_name_too_long_is_refused(tmp_path, capsys):
    argv = ["part", "cone", "-o", str(tmp_path / ("d" * 300) / "p.toml")]
    assert main(argv) == 2
    assert "300 bytes long" in _err_line(capsys)
    assert os.listdir(tmp_path) == []
