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
