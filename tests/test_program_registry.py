"""roboisf.programs.registry: the built-in formats, the registry's refusals, and a new format
registered in one place picked up by the export and the CLI (companion files claimed too)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from roboisf.cli.main import main
from roboisf.errors import InputError
from roboisf.parts import Cone
from roboisf.programs.export import check_program_name, infer_format, write_toolpath
from roboisf.programs.registry import (
    ProgramFormat,
    WriteOptions,
    find_format,
    get_format,
    program_formats,
    register,
    unregister,
)
from roboisf.toolpath import step_down

SMALL_CONE = ["--opening-diameter", "60", "--wall-angle", "60", "--depth", "5", "--spacing", "3"]


def test_the_built_in_formats():
    fmts = program_formats()
    assert [f.name for f in fmts] == ["csv", "gcode", "rapid", "krl", "fanuc"]
    assert {f.name for f in fmts if f.kind == "robot"} == {"rapid", "krl", "fanuc"}
    assert get_format("krl").companions == (".dat",)
    assert get_format("krl").output_files(Path("a/p.src")) == [Path("a/p.src"), Path("a/p.dat")]
    assert all(f.read is not None and f.check_name is not None for f in fmts if f.kind == "robot")
    assert find_format(Path("X.MOD")) is get_format("rapid")  # any case
    assert find_format(Path("x.modx")) is None  # .modx is read, never written
    from roboisf.toolpath.commanded import robot_program_format

    assert robot_program_format(Path("x.modx")) is get_format("rapid")
    assert robot_program_format(Path("x.nc")) is None  # a CNC program is no robot program
    assert find_format(Path("x.unknown")) is None and find_format("x.src", "nope") is None


def test_suffix_inference_and_its_errors():
    assert infer_format("p.NGC") == "gcode" and infer_format("p.txt", "gcode") == "gcode"
    with pytest.raises(InputError, match=r"a KRL program must be written to a \.src file"):
        infer_format("p.txt", "krl")
    with pytest.raises(InputError, match="unknown format 'x'; expected one of csv, gcode, rapid"):
        infer_format("p.csv", "x")
    with pytest.raises(InputError, match=r"suffix '\.txt'.*\.src \(krl\)"):
        infer_format("p.txt")
    with pytest.raises(InputError, match="RAPID module name"):
        check_program_name("1p.mod", "rapid")
    with pytest.raises(InputError, match="FANUC program name"):
        check_program_name("p-1.ls", "fanuc")
    check_program_name("1p.csv", "csv")  # no name rule


def _noop(tp, path, o):  # pragma: no cover - never called
    return [path]


def test_the_registry_refuses_clashes_and_bad_suffixes():
    with pytest.raises(ValueError, match="already registered"):
        register(ProgramFormat("krl", (".krl2",), "robot", "x", _noop))
    with pytest.raises(ValueError, match=r"suffix \.src is 'krl'"):
        register(ProgramFormat("krl2", (".src",), "robot", "x", _noop))
    with pytest.raises(ValueError, match=r"suffix \.modx is 'rapid'"):
        register(ProgramFormat("abb2", (".modx",), "robot", "x", _noop))
    with pytest.raises(ValueError, match="lower case"):
        ProgramFormat("t", ("TXT",), "cnc", "x", _noop)
    with pytest.raises(ValueError, match="kind"):
        ProgramFormat("t", (".t",), "plc", "x", _noop)  # type: ignore[arg-type]
    assert "krl2" not in {f.name for f in program_formats()}


@pytest.fixture
def toy():
    """A toy CNC format: the tips in mm, one per line, and a companion ``.aux`` with the options
    the writer was given. Registered for one test."""
    seen: list[WriteOptions] = []

    def write(tp, path: Path, o: WriteOptions) -> list[Path]:
        seen.append(o)
        np.savetxt(path, tp.tip * 1e3, fmt="%.3f")
        aux = path.with_suffix(".aux")
        aux.write_text(f"{o.work_offset} {o.safe_height}\n")
        return [path, aux]

    fmt = register(ProgramFormat("toy", (".toy",), "cnc", "toy", write, companions=(".aux",)))
    try:
        yield fmt, seen
    finally:
        unregister("toy")
    assert "toy" not in {f.name for f in program_formats()}


def test_a_new_format_is_picked_up_by_the_export(toy, tmp_path):
    _, seen = toy
    tp = step_down(Cone(depth=4e-3), 5e-3, 1e-3, spacing=3e-3)
    fmt, files = write_toolpath(tp, tmp_path / "p.toy", work_offset="G55", safe_height=0.02)
    assert fmt == "toy" and files == [tmp_path / "p.toy", tmp_path / "p.aux"]
    np.testing.assert_allclose(np.loadtxt(files[0]), tp.tip * 1e3, atol=5e-4)
    assert seen[-1].work_offset == "G55" and seen[-1].safe_height == 0.02


def test_a_new_format_is_picked_up_by_the_cli(toy, tmp_path, capsys):
    out = tmp_path / "cone.toy"
    assert main(["toolpath", "cone", *SMALL_CONE, "-o", str(out)]) == 0
    assert "(toy)" in capsys.readouterr().out
    assert (tmp_path / "cone.aux").read_text() == "G54 0.01\n"
    # the companion is claimed before generating: a user's cone2.aux is never overwritten
    user = tmp_path / "cone2.aux"
    user.write_text("mine\n")
    assert main(["toolpath", "cone", *SMALL_CONE, "-o", str(tmp_path / "cone2.toy")]) == 2
    assert "cone2.aux" in capsys.readouterr().err
    assert user.read_text() == "mine\n" and not (tmp_path / "cone2.toy").exists()
    # --format picks it for any file name (no suffix rule for this format)
    assert main(["toolpath", "cone", *SMALL_CONE, "-f", "toy", "-o", str(tmp_path / "c.txt")]) == 0
    assert (tmp_path / "c.aux").is_file()
