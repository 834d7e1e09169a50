"""docs/extending.md: the worked example of a controller format runs as written.

The code block of the page is loaded as a module (which registers the ``urscript`` format); the
CLI, the export and the commanded-program reader then pick the format up without any other change.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from roboisf.cli.main import main
from roboisf.io.toolpath_csv import read_toolpath_csv
from roboisf.programs.registry import find_format, get_format, program_formats, unregister

DOC = Path(__file__).resolve().parents[1] / "docs" / "extending.md"
SMALL_CONE = ["--opening-diameter", "60", "--wall-angle", "60", "--depth", "5", "--spacing", "3"]
ROBOT = ["--placement", "1600,0,600", "--tool", "200"]


def _example_source() -> str:
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    (block,) = [b for b in blocks if b.startswith("# roboisf_urscript.py")]
    return block


@pytest.fixture
def urscript(tmp_path):
    """The page's module, imported from a file as a user's module would be; unregistered after."""
    module = tmp_path / "roboisf_urscript.py"
    module.write_text(_example_source(), encoding="utf-8")
    spec = importlib.util.spec_from_file_location("roboisf_urscript", module)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["roboisf_urscript"] = mod
    try:
        spec.loader.exec_module(mod)
        yield mod
    finally:
        unregister("urscript")
        sys.modules.pop("roboisf_urscript", None)


def test_the_example_is_one_registered_format(urscript):
    fmt = get_format("urscript")
    assert fmt in program_formats() and program_formats()[-1] is fmt  # rank 50: listed last
    assert find_format(Path("x.script")) is fmt and fmt.kind == "robot"


def test_the_cli_writes_the_example_format_and_it_reads_back(urscript, tmp_path):
    script, csv = tmp_path / "cone.script", tmp_path / "cone.csv"
    assert main(["toolpath", "cone", *SMALL_CONE, *ROBOT, "-o", str(script)]) == 0
    assert main(["toolpath", "cone", *SMALL_CONE, "-o", str(csv)]) == 0
    tp = read_toolpath_csv(csv)
    prog = get_format("urscript").read(script)  # type: ignore[misc]
    assert len(prog) == len(tp)  # one movel per point; the movej approach/retract are not read
    assert np.max(np.abs(prog.tip - tp.tip)) <= 0.5e-6 + 1e-12  # 1 µm program resolution
    assert np.allclose(prog.T_base_work[:3, 3], [1.6, 0.0, 0.6]) and prog.tool.length == 0.2
    assert np.allclose(prog.R_work_tool[:, 2, 2], -1.0)  # tool axis down into the sheet
    assert prog.feed == pytest.approx(tp.feed, abs=1e-6)


def test_the_format_flag_and_the_name_check_of_the_example(urscript, tmp_path, capsys):
    out = tmp_path / "cone.txt"
    assert main(["toolpath", "cone", *SMALL_CONE, *ROBOT, "-f", "urscript", "-o", str(out)]) == 2
    assert "a URScript program must be written to a .script file" in capsys.readouterr().err
    bad = tmp_path / "1cone.script"
    assert main(["toolpath", "cone", *SMALL_CONE, *ROBOT, "-o", str(bad)]) == 2
    assert "not a URScript function name" in capsys.readouterr().err
    assert not bad.exists() and not out.exists()


def test_an_existing_program_is_kept_without_overwrite(urscript, tmp_path, capsys):
    script = tmp_path / "cone.script"
    script.write_text("the user's own program\n")
    assert main(["toolpath", "cone", *SMALL_CONE, *ROBOT, "-o", str(script)]) == 2
    assert script.read_text() == "the user's own program\n"


def test_a_compensated_command_in_the_example_format_is_read_back(urscript, tmp_path):
    from roboisf.toolpath.commanded import robot_program_format

    assert robot_program_format(tmp_path / "compensated.script") is get_format("urscript")
    unregister("urscript")
    assert robot_program_format(tmp_path / "compensated.script") is None
