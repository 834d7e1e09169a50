"""The roboisf tables (toolpath, thickness, calibration CSV) as spreadsheets write them:
semicolons or tabs, decimal commas, names in any case, a free-text block, a BOM — with the same
strict checks (every cell a number, the line named)."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.io.table import read_table

DEPTH = [1.0, 2.5, 4.0]
THICK = [1.21, 1.0625, 0.5]


@pytest.mark.parametrize(
    ("sep", "dec"), [(",", "."), (";", "."), (";", ","), ("\t", ","), ("\t", ".")]
)
def test_separator_decimal_case_bom_and_preamble(tmp_path, sep, dec):
    rows = "".join(
        f"{str(d).replace('.', dec)}{sep}{str(t).replace('.', dec)}\n"
        for d, t in zip(DEPTH, THICK, strict=True)
    )
    text = "\ufeffGauge export 2024-03-14\nOperator: A.B.\n# units: length=mm\n"
    text += f"Depth{sep}THICKNESS\n" + rows
    f = tmp_path / "t.csv"
    f.write_text(text, encoding="utf-8")
    t = read_table(f, ("depth", "thickness"))
    np.testing.assert_array_equal(t.column("depth"), DEPTH)
    np.testing.assert_array_equal(t.column("thickness"), THICK)
    assert t.meta["units"] == "length=mm" and t.header_line == 4
    assert list(t.lines) == [5, 6, 7]


def test_bad_cell_still_named(tmp_path):
    f = tmp_path / "t.csv"
    f.write_text("depth;thickness\n1,0;1,2\n2,0;abc\n")
    with pytest.raises(InputError, match=r"t\.csv:3 \[thickness\]: not a number: 'abc'"):
        read_table(f, ("depth", "thickness"))
    g = tmp_path / "g.csv"
    g.write_text("depth;thickness\n1,0;1,2\n2,0\n")
    with pytest.raises(InputError, match=r"g\.csv:3: expected 2 columns"):
        read_table(g, ("depth", "thickness"))


def test_missing_column_named_on_the_first_line(tmp_path):
    f = tmp_path / "t.csv"
    f.write_text("depth;thick\n1;2\n")
    with pytest.raises(InputError, match=r"t\.csv:1 \[thickness\]: missing column"):
        read_table(f, ("depth", "thickness"))


@pytest.mark.parametrize("sep", [",", ";", "\t"])
@pytest.mark.parametrize(
    ("body", "lines"),
    [
        ("1,1.5\n2,2.5\n3,3.5\n", [3, 4, 5]),
        ("1,1.5\n\n2,2.5\n\n\n3,3.5\n", [3, 5, 8]),  # empty lines inside: the fast parser
        ("1,1.5\n   \n2,2.5\n3,3.5\n", [3, 5, 6]),  # skips them, so the careful reader counts
        ("1,1.5\n2,2.5\n3,3.5\n\n\n", [3, 4, 5]),
        ("1,1.5\r\n2,2.5\r\n3,3.5", [3, 4, 5]),  # CRLF, no newline at the end
        ('"1","1.5"\n2,2.5\n3,3.5\n', [3, 4, 5]),
    ],
    ids=["plain", "empty-inside", "blank-inside", "blank-after", "crlf", "quoted"],
)
def test_rows_keep_their_file_lines_whichever_parser_reads_them(tmp_path, sep, body, lines):
    f = tmp_path / "t.csv"
    f.write_bytes(("# units: length=mm\ndepth,thickness\n" + body).replace(",", sep).encode())
    t = read_table(f, ("depth", "thickness"))
    np.testing.assert_array_equal(t.column("depth"), [1, 2, 3])
    np.testing.assert_array_equal(t.column("thickness"), [1.5, 2.5, 3.5])
    assert list(t.lines) == lines
    # a bad value after a blank line is named on its physical line
    bad = body.replace("3.5", "nan")
    f.write_bytes(("# units: length=mm\ndepth,thickness\n" + bad).replace(",", sep).encode())
    with pytest.raises(InputError, match=rf"t\.csv:{lines[2]} \[thickness\]: nan is not a finite"):
        read_table(f, ("depth", "thickness"))
