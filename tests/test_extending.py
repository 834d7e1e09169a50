"""docs/extending.md: the worked examples — a controller format, a force-log profile, a part
kind — run as written.

Each code block of the page is loaded as a module (which registers its format); the CLI, the
readers, the study, the virtual cell and the export then pick the format up without any other
change, and unregistered it is gone.
"""

from __future__ import annotations

import contextlib
import importlib.util
import math
import re
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from roboisf.cam.toolpath_csv import read_toolpath_csv
from roboisf.cli.main import main
from roboisf.errors import InputError
from roboisf.formats import get_file_format, unregister_format
from roboisf.logs.forcelog import ForceLog, detect_force_format, read_force_log
from roboisf.programs.registry import find_format, get_format, program_formats, unregister

DOC = Path(__file__).resolve().parents[1] / "docs" / "extending.md"
SMALL_CONE = ["--opening-diameter", "60", "--wall-angle", "60", "--depth", "5", "--spacing", "3"]
ROBOT = ["--placement", "1600,0,600", "--tool", "200"]


def _example_source(name: str = "roboisf_urscript") -> str:
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    (block,) = [b for b in blocks if b.startswith(f"# {name}.py")]
    return block


@contextlib.contextmanager
def _example(name: str, tmp_path: Path, kind: str, fmt: str) -> Iterator[Any]:
    """The page's module ``name``, imported from a file as a user's module would be (which
    registers the ``kind`` format ``fmt``); unregistered and forgotten after."""
    module = tmp_path / f"{name}.py"
    module.write_text(_example_source(name), encoding="utf-8")
    spec = importlib.util.spec_from_file_location(name, module)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    try:
        spec.loader.exec_module(mod)
        yield mod
    finally:
        unregister_format(kind, fmt)
        sys.modules.pop(name, None)


@pytest.fixture
def urscript(tmp_path):
    with _example("roboisf_urscript", tmp_path, "robot", "urscript") as mod:
        yield mod


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


# -- a force-log profile -----------------------------------------------------------------------


@pytest.fixture
def labview(tmp_path):
    with _example("roboisf_labview_forces", tmp_path, "force_log", "labview") as mod:
        yield mod


def _log():
    rng = np.random.default_rng(5)
    t = 7.25 + np.arange(300) / 250.0
    return ForceLog(t, rng.normal(scale=[80, 80, 300, 3, 3, 1], size=(300, 6)), "sensor")


def test_the_profile_example_round_trips_through_auto_detection(labview, tmp_path):
    log, f = _log(), tmp_path / "forces.csv"
    fmt = get_file_format("force_log", "labview")
    fmt.writer(log, f)  # type: ignore[misc]
    assert f.read_text().startswith("Zeitstempel;Kraft_X;")
    assert detect_force_format(f)[0] == "labview"  # no format key needed
    back = read_force_log(f)  # the automatic detection, as a study reads it
    assert back.profile == "labview" and back.moments_known
    r = fmt.rounding
    assert r is not None
    np.testing.assert_allclose(back.time, log.time, rtol=0, atol=r["time"] * (1 + 1e-6))  # ms → s
    np.testing.assert_allclose(back.wrench, log.wrench, rtol=r["value"] * (1 + 1e-6), atol=0)


def test_the_profile_example_is_offered_everywhere_then_gone(labview, tmp_path):
    from roboisf.logs.forcelog import force_formats, write_force_log
    from roboisf.virtual.equipment import Equipment

    assert "labview" in force_formats()  # a study's [runs.X.forces] format
    assert Equipment(robot_force_profile="labview").robot_force_profile == "labview"
    write_force_log(_log(), tmp_path / "x.csv", profile="labview")
    assert detect_force_format(tmp_path / "x.csv")[0] == "labview"
    unregister_format("force_log", "labview")
    assert "labview" not in force_formats()
    with pytest.raises(InputError, match="no force-log format recognised"):
        read_force_log(tmp_path / "x.csv")  # without the profile, the names are unknown
    with pytest.raises(InputError, match="expected one of"):
        Equipment(robot_force_profile="labview")


# -- a part kind -------------------------------------------------------------------------------

DOME = '[part]\nkind = "dome"\nsphere_radius = 60.0\ndepth = 20.0\n'


@pytest.fixture
def dome(tmp_path):
    with _example("roboisf_dome", tmp_path, "part", "dome") as mod:
        yield mod


def test_the_part_example_is_the_sphere(dome, tmp_path):
    from roboisf.parts.io import load_part, part_kinds

    assert "dome" in part_kinds()
    (tmp_path / "dome.toml").write_text(DOME)
    part = load_part(tmp_path / "dome.toml")
    R, h = 0.060, 0.020
    assert part.kind == "dome" and part.depth == pytest.approx(h, abs=1e-12)
    assert part.r[0] == pytest.approx(math.sqrt(h * (2 * R - h)), abs=1e-12)  # the rim
    # points of the sphere are on the part within the stated chord error
    phi = np.random.default_rng(1).uniform(0, math.asin(part.r[0] / R), 400)
    th = np.random.default_rng(2).uniform(0, 2 * math.pi, 400)
    s = R * np.sin(phi)
    pts = np.column_stack([s * np.cos(th), s * np.sin(th), (R - h) - R * np.cos(phi)])
    d = part.signed_distance(pts)
    assert np.max(np.abs(d)) <= dome.CHORD_ERROR * (1 + 1e-6)
    assert np.max(np.abs(d)) > 0.05 * dome.CHORD_ERROR  # a polyline: not exact, but close


def test_the_part_example_round_trips_and_refuses_bad_tables(dome, tmp_path):
    from roboisf.parts.io import load_part, part_from_dict, save_part

    (tmp_path / "dome.toml").write_text(DOME)
    part = load_part(tmp_path / "dome.toml")
    save_part(part, tmp_path / "again.toml")
    assert 'kind = "dome"' in (tmp_path / "again.toml").read_text()
    assert load_part(tmp_path / "again.toml") == part
    with pytest.raises(InputError, match=r"unknown key.*radius.*expected.*sphere_radius"):
        part_from_dict({"kind": "dome", "radius": 60.0, "depth": 20.0})
    with pytest.raises(InputError, match="depth <= sphere_radius"):
        part_from_dict({"kind": "dome", "sphere_radius": 10.0, "depth": 20.0})
    unregister_format("part", "dome")
    with pytest.raises(InputError, match="unknown part kind 'dome'"):
        load_part(tmp_path / "dome.toml")


def test_the_cli_makes_a_toolpath_for_the_part_example(dome, tmp_path):
    (tmp_path / "dome.toml").write_text(DOME)
    out = tmp_path / "dome.csv"
    assert main(["toolpath", "--part", str(tmp_path / "dome.toml"), "-o", str(out)]) == 0
    tp = read_toolpath_csv(out)
    assert tp.tip[:, 2].min() == pytest.approx(-0.020, abs=1e-3)  # down to the pole
