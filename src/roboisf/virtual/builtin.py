"""The built-in virtual cells, one registry: ``roboisf virtual-cell PART``, ``compensate
--virtual`` and ``online --virtual`` loop over it.

Each entry names a cell (the command-line value), the function that builds it (imported on first
use: this module loads no numeric library, so the command line's ``--help`` stays fast), a
one-line description and whether the shipped ``paper`` truth scenario exists for it
(``virtual/scenarios/paper_<name>.toml``). Adding a built-in cell is one :class:`BuiltinCell`
in :data:`BUILTIN_CELLS`. Any part file (``roboisf part …``) makes a cell too:
:func:`roboisf.virtual.cell.part_cell`.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from roboisf.errors import InputError

if TYPE_CHECKING:
    from roboisf.virtual.cell import VirtualCell

__all__ = [
    "BUILTIN_CELLS",
    "BuiltinCell",
    "builtin_names",
    "make_builtin_cell",
    "paper_scenario_names",
]


@dataclass(frozen=True)
class BuiltinCell:
    """One built-in virtual cell.

    name : the command-line value (``roboisf virtual-cell NAME``)
    factory : ``"module:function"``, a function ``(**overrides) -> VirtualCell``
    summary : what the cell forms, one line (mm, deg)
    paper_scenario : the ``paper`` truth scenario exists for this cell
    """

    name: str
    factory: str
    summary: str
    paper_scenario: bool = False

    def make(self, **overrides: Any) -> VirtualCell:
        """The cell, with ``overrides`` (settings of :func:`roboisf.virtual.cell.virtual_cell`)."""
        module, function = self.factory.split(":")
        make = getattr(importlib.import_module(module), function)
        cell: VirtualCell = make(**overrides)
        return cell


BUILTIN_CELLS: dict[str, BuiltinCell] = {
    c.name: c
    for c in (
        BuiltinCell(
            "cone",
            "roboisf.virtual.cell:paper_cone_cell",
            "the paper's cone: Ø87 mm, 71°, 102.97 mm deep",
            paper_scenario=True,
        ),
        BuiltinCell(
            "vwacf",
            "roboisf.virtual.cell:paper_vwacf_cell",
            "the paper's variable-wall-angle cone frustum: Ø88.15 mm, 0 → 90°",
            paper_scenario=True,
        ),
        BuiltinCell(
            "pyramid",
            "roboisf.virtual.cell:pyramid_cell",
            "a square truncated pyramid: 100 × 100 mm, 60°, 40 mm deep, 10 mm corner radius",
        ),
    )
}


def builtin_names() -> tuple[str, ...]:
    """The built-in cells' names, in registry order (``("cone", "vwacf", "pyramid")``)."""
    return tuple(BUILTIN_CELLS)


def paper_scenario_names() -> tuple[str, ...]:
    """The built-in cells the ``paper`` truth scenario exists for."""
    return tuple(n for n, c in BUILTIN_CELLS.items() if c.paper_scenario)


def make_builtin_cell(name: str, *, field: str = "PART", **overrides: Any) -> VirtualCell:
    """The built-in cell ``name`` with ``overrides``; an unknown name is an
    :class:`~roboisf.errors.InputError` on ``field`` listing the built-in cells."""
    if name not in BUILTIN_CELLS:
        raise InputError(
            f"unknown virtual cell {name!r}; expected one of {', '.join(BUILTIN_CELLS)}",
            field=field,
        )
    return BUILTIN_CELLS[name].make(**overrides)
