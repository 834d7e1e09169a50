"""Long instrument exports: read in blocks after a look at the file's head
(:func:`roboisf.io.table.read_log_table`). The block reader and the whole-file reader must give
the same bits, the same units and layout, and name a bad line the same way. Each case is written
small and read twice: with a head shorter than the file (blocks) and with the whole file."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.io import table
from roboisf.logs.forcelog import read_force_log
from roboisf.logs.jointlog import read_joint_log

N = 400  # rows: the file is ~20 kB, far above the 4 kB head of the block reader below


def _rows(sep: str, dec: str, extra: str = "") -> list[str]:
    rng = np.random.default_rng(4)
    t = np.arange(N) * 1e-3
    w = rng.normal(size=(N, 6)) * [50, 50, 800, 3, 3, 1]
    out = []
    for k in range(N):
        cells = [f"{t[k]:.3f}", *(f"{v:.6g}" for v in w[k])]
        if dec == ",":
            cells = [c.replace(".", ",") for c in cells]
        out.append(sep.join(cells) + extra)
    return out


CASES = {
    "generic-comma": ("Time [s],Fx [N],Fy [N],Fz [N],Mx [N*m],My [N*m],Mz [N*m]", ",", ".", ""),
    "kistler-tab-decimal-comma": (
        "Time\tFx\tFy\tFz\tMx\tMy\tMz\ns\tN\tN\tN\tN*m\tN*m\tN*m",
        "\t",
        ",",
        "",
    ),
    "blanks": (
        "# units: time=s force=N moment=N*m\n  time   Fx   Fy   Fz   Mx   My   Mz",
        " ",
        ".",
        "",
    ),
    "semicolon-status": (
        "Zeit [s];Fx [N];Fy [N];Fz [N];Mx [N*m];My [N*m];Mz [N*m];Status",
        ";",
        ",",
        ";OK",
    ),
}


def _write(path, case, rows=None):
    header, sep, dec, extra = CASES[case]
    pre = "Messung 2026-11-27\nSample rate: 1000 Hz\n\n"
    body = rows if rows is not None else _rows(sep, dec, extra)
    path.write_text(pre + header + "\n" + "\n".join(body) + "\n", encoding="utf-8")


def _both(monkeypatch, read, path):
    """(block reader, whole-file reader) results or their errors."""
    out = []
    for head in (4096, 1 << 30):
        monkeypatch.setattr(table, "_HEAD_BYTES", head)
        try:
            out.append(read(path))
        except InputError as e:
            out.append(e)
    return out


@pytest.mark.parametrize("case", list(CASES))
def test_blocks_equal_the_whole_file(tmp_path, monkeypatch, case):
    f = tmp_path / "log.txt"
    _write(f, case)
    calls = []
    real = table._log_body_blocks
    monkeypatch.setattr(table, "_log_body_blocks", lambda *a: calls.append(1) or real(*a))
    fast, whole = _both(monkeypatch, read_force_log, f)
    assert calls == [1]  # the block reader ran (and the whole-file reader did not call it)
    np.testing.assert_array_equal(fast.time, whole.time)
    np.testing.assert_array_equal(fast.wrench, whole.wrench)
    assert fast.profile == whole.profile and fast.moments_known
    assert fast.time.size == N


@pytest.mark.parametrize(
    ("edit", "line_of_row"),
    [
        (lambda rows: rows.__setitem__(300, rows[300].replace("0.3", "x.3", 1)), 300),
        (lambda rows: rows.__setitem__(350, rows[350].rsplit(",", 2)[0]), 350),  # short row
    ],
    ids=["not-a-number", "short-row"],
)
def test_a_bad_row_deep_in_the_file_is_named_on_its_line(tmp_path, monkeypatch, edit, line_of_row):
    f = tmp_path / "log.csv"
    rows = _rows(",", ".")
    edit(rows)
    _write(f, "generic-comma", rows)
    fast, whole = _both(monkeypatch, read_force_log, f)
    assert isinstance(fast, InputError) and isinstance(whole, InputError)
    assert str(fast) == str(whole)
    assert f"log.csv:{5 + line_of_row}" in str(fast)  # 3 preamble lines, header, then the rows


def test_blank_lines_inside_keep_every_row_on_its_line(tmp_path, monkeypatch):
    f = tmp_path / "log.csv"
    rows = _rows(",", ".")
    rows[200] = rows[200] + "\n"  # an empty line after row 200
    rows[201] = rows[201].replace(rows[201].split(",")[0], "nan", 1)
    _write(f, "generic-comma", rows)
    fast, whole = _both(monkeypatch, read_force_log, f)
    assert str(fast) == str(whole)
    assert "log.csv:207 [time]: nan is not a finite number" in str(fast)  # 5 + 201 + 1 blank


def test_joint_log_in_blocks(tmp_path, monkeypatch):
    f = tmp_path / "joints.csv"
    rng = np.random.default_rng(2)
    q = rng.uniform(-90, 90, size=(N, 6))
    body = "\n".join(",".join([f"{k * 4e-3:.3f}", *(f"{v:.5f}" for v in q[k])]) for k in range(N))
    f.write_text(
        "# units: time=s angle=deg\ntime,q1,q2,q3,q4,q5,q6\n" + body + "\n", encoding="utf-8"
    )
    fast, whole = _both(monkeypatch, read_joint_log, f)
    np.testing.assert_array_equal(fast.time, whole.time)
    np.testing.assert_array_equal(fast.q, whole.q)
    np.testing.assert_allclose(np.degrees(fast.q), np.round(q, 5), atol=1e-9)


@pytest.mark.parametrize("case", list(CASES))
def test_the_table_is_the_same_field_by_field(tmp_path, monkeypatch, case):
    from roboisf.formats import get_file_format

    f = tmp_path / "log.txt"
    _write(f, case)
    spec = get_file_format("force_log", "generic").spec
    match, req = spec.match, spec.required
    fast, whole = _both(monkeypatch, lambda p: table.read_log_table(p, match, req), f)
    for name in ("meta", "preamble", "columns", "names", "units", "header_line", "separator"):
        assert getattr(fast, name) == getattr(whole, name), name
    assert fast.decimal == whole.decimal == CASES[case][2]
    np.testing.assert_array_equal(fast.lines, whole.lines)
    assert fast.lines[0] == whole.header_line + 1 + (case == "kistler-tab-decimal-comma")
    assert fast.data.keys() == whole.data.keys()
    for k in fast.data:
        np.testing.assert_array_equal(fast.data[k], whole.data[k])


def test_a_header_past_the_head_is_still_found(tmp_path, monkeypatch):
    """A long free-text preamble pushes the header past the block reader's head: the file is
    read whole, not refused."""
    f = tmp_path / "log.csv"
    header, sep, dec, _ = CASES["generic-comma"]
    pre = "".join(f"Note {k}: " + "x" * 120 + "\n" for k in range(60))  # ~8 kB
    f.write_text(pre + header + "\n" + "\n".join(_rows(sep, dec)) + "\n", encoding="utf-8")
    fast, whole = _both(monkeypatch, read_force_log, f)
    assert not isinstance(fast, InputError), fast
    np.testing.assert_array_equal(fast.wrench, whole.wrench)


def test_other_line_breaks_go_to_the_whole_file_reader(tmp_path, monkeypatch):
    """Lines the head would count differently from the whole-file reader (a lone CR, as old
    Mac exports end them, in the preamble) must not shift the rows the blocks skip to."""
    f = tmp_path / "log.csv"
    header, sep, dec, _ = CASES["generic-comma"]
    text = "Logger\rSample rate: 1000 Hz\n" + header + "\n" + "\n".join(_rows(sep, dec)) + "\n"
    f.write_text(text, encoding="utf-8", newline="")
    fast, whole = _both(monkeypatch, read_force_log, f)
    assert not isinstance(whole, InputError), whole
    assert not isinstance(fast, InputError), fast
    np.testing.assert_array_equal(fast.time, whole.time)
    np.testing.assert_array_equal(fast.wrench, whole.wrench)
