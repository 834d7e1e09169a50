"""The built-in virtual cells are one registry (``roboisf.virtual.builtin``): every command that
takes a built-in cell loops over it, so one new entry reaches ``virtual-cell``, ``compensate
--virtual`` and ``online --virtual`` alike."""

from __future__ import annotations

import importlib
import sys
import types
from pathlib import Path

import pytest

import roboisf.virtual
from roboisf.cli.main import main
from roboisf.errors import InputError
from roboisf.virtual.builtin import (
    BUILTIN_CELLS,
    BuiltinCell,
    builtin_names,
    make_builtin_cell,
    paper_scenario_names,
)


def test_the_registry_names_the_built_in_cells_and_their_factories():
    assert builtin_names() == ("cone", "vwacf", "pyramid")
    for cell in BUILTIN_CELLS.values():
        module, function = cell.factory.split(":")
        assert callable(getattr(importlib.import_module(module), function)), cell.factory


def test_the_paper_scenario_flag_matches_the_shipped_scenario_files():
    folder = Path(roboisf.virtual.__file__).parent / "scenarios"
    shipped = {p.stem.removeprefix("paper_") for p in folder.glob("paper_*.toml")}
    assert set(paper_scenario_names()) == shipped == {"cone", "vwacf"}


def test_an_unknown_cell_names_the_field_and_the_built_in_cells():
    with pytest.raises(InputError, match=r"\[--virtual\].*'dome'.*cone, vwacf, pyramid"):
        make_builtin_cell("dome", field="--virtual")
    from roboisf.virtual.cell import paper_scenario_cell

    with pytest.raises(InputError, match="expected 'cone' or 'vwacf', got 'pyramid'"):
        paper_scenario_cell("pyramid")


@pytest.fixture
def probe_cell(monkeypatch):
    """A new built-in cell, ``probe``, whose factory refuses with a message of its own: one
    entry in the registry, nothing else."""
    module = types.ModuleType("probe_cells")

    def make(**overrides):
        raise InputError(f"the probe cell was built with {sorted(overrides)}", field="probe")

    module.make = make  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "probe_cells", module)
    monkeypatch.setitem(BUILTIN_CELLS, "probe", BuiltinCell("probe", "probe_cells:make", "a test"))


@pytest.mark.parametrize(
    "args",
    [
        ["virtual-cell", "probe", "-o", "{tmp}/study"],
        ["compensate", "--virtual", "probe", "-o", "{tmp}/comp"],
        ["online", "-c", "egm", "--virtual", "probe", "-o", "{tmp}/log.parquet"],
    ],
    ids=["virtual-cell", "compensate", "online"],
)
def test_one_registry_entry_reaches_every_command(tmp_path, capsys, probe_cell, args):
    code = main([a.format(tmp=tmp_path) for a in args])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "the probe cell was built with" in err and "Traceback" not in err


def test_without_the_entry_the_commands_refuse_the_name(tmp_path, capsys):
    for args in (
        ["virtual-cell", "probe", "-o", str(tmp_path / "s")],
        ["compensate", "--virtual", "probe", "-o", str(tmp_path / "c")],
        ["online", "-c", "egm", "--virtual", "probe", "-o", str(tmp_path / "l.parquet")],
    ):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert "probe" in err and "cone" in err and "probe cell was built" not in err
