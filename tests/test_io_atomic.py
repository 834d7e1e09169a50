"""Atomic outputs: nothing half-written, ordinary permissions, staged folders."""

import os
import stat

import pytest

from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write, check_not_input, staged_directory
from roboisf.io.outdir import MARKER


def test_failed_write_leaves_the_old_file(tmp_path):
    p = tmp_path / "out.txt"
    p.write_text("old")
    with pytest.raises(RuntimeError), atomic_write(p) as fh:
        fh.write("new, half")
        raise RuntimeError("boom")
    assert p.read_text() == "old"
    assert [f.name for f in tmp_path.iterdir()] == ["out.txt"]


def test_written_file_has_umask_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        with atomic_write(tmp_path / "a.txt") as fh:
            fh.write("x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o644


def test_staged_directory_replaces_only_on_success(tmp_path):
    out = tmp_path / "res"
    with staged_directory(out) as d:
        (d / "a").write_text("1")
    assert (out / "a").read_text() == "1"
    assert stat.S_IMODE(out.stat().st_mode) & 0o055 == 0o055  # others can read and enter
    with pytest.raises(ValueError), staged_directory(out) as d:
        (d / "b").write_text("2")
        raise ValueError
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "a"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


def test_output_may_not_overwrite_an_input(tmp_path):
    f = tmp_path / "in.csv"
    f.write_text("x")
    with pytest.raises(InputError, match="overwrite an input"):
        check_not_input(f, [tmp_path / "other.csv", f])
