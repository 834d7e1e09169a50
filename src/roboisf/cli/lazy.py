"""Command groups that start at once (issue #16).

:class:`LazyGroup` is click's "lazy loading subcommands" pattern on typer: the root group lists
its commands from a static table (:class:`LazyCommand`: name, module, one-line help) and imports
a command's module only when that command runs or shows its own ``--help``; ``roboisf --help``
imports none of them. ``tests/test_cli_startup.py`` builds the real commands from the table's
modules and checks that the table lists the same commands, in the same order, with the same
one-line help, so the table cannot drift from the code.

:class:`FullHelpGroup` lists each sub-command with its whole first help paragraph; click's plain
help formatter would cut it to the terminal width minus the name, ending in "...".
"""

from __future__ import annotations

import difflib
import importlib
import inspect
import sys
from dataclasses import dataclass
from typing import Any

import typer
import typer.main
from typer.core import MarkupMode, TyperGroup

__all__ = [
    "DEFERRED_MODULES",
    "FullHelpGroup",
    "LazyCommand",
    "LazyGroup",
    "defer_unused_imports",
    "load_command",
    "one_line_help",
]


@dataclass(frozen=True)
class LazyCommand:
    """One command of a :class:`LazyGroup`, known without importing its module.

    Attributes
    ----------
    name : str
        The command's name on the command line (``"tool-stiffness"``).
    module : str
        The module under ``roboisf.cli`` whose ``register(app)`` adds it (``"fem"``).
    help : str
        Its first help paragraph on one line, as ``roboisf --help`` lists it.
    """

    name: str
    module: str
    help: str


def one_line_help(command: Any) -> str:
    """The first paragraph of a click command's help, whitespace collapsed to single spaces.

    ``command`` is a click/typer command (typer may vendor its own click, hence ``Any``).
    """
    text = command.short_help or command.help or ""
    return " ".join(inspect.cleandoc(text).split("\n\n")[0].split())


def load_command(entry: LazyCommand, markup_mode: MarkupMode = None) -> Any:
    """Import ``roboisf.cli.<entry.module>``, register it on a fresh app, return the command.

    Raises
    ------
    LookupError
        The module's ``register`` adds no command called ``entry.name`` (a stale table).
    """
    module = importlib.import_module(f"roboisf.cli.{entry.module}")
    app = typer.Typer(rich_markup_mode=markup_mode, add_completion=False)
    module.register(app)
    command = typer.main.get_group(app).commands.get(entry.name)
    if command is None:
        raise LookupError(f"roboisf.cli.{entry.module}.register adds no command {entry.name!r}")
    return command


class FullHelpGroup(TyperGroup):
    """A typer group whose ``--help`` lists every sub-command with its whole first paragraph."""

    def _listed_help(self, ctx: Any, name: str) -> str | None:
        command = self.get_command(ctx, name)
        if command is None or command.hidden:
            return None
        return one_line_help(command)

    def get_help_option(self, ctx: Any) -> Any:
        # a group's --help when not given is None; typer (0.29) coerces every non-bool value
        # through a pydantic TypeAdapter, so `roboisf analyze --help` imported pydantic (0.1 s)
        # for the root's absent --help. False is the same "not given" to click's help callback.
        option = super().get_help_option(ctx)
        if option is not None and option.default is None:
            option.default = False
        return option

    def format_commands(self, ctx: Any, formatter: Any) -> None:
        rows = []
        for name in self.list_commands(ctx):
            text = self._listed_help(ctx, name)
            if text is not None:
                rows.append((name, text))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


class LazyGroup(FullHelpGroup):
    """A :class:`FullHelpGroup` whose commands in :attr:`lazy` are imported on first use.

    Subclass it with ``lazy`` set and pass the subclass as ``typer.Typer(cls=...)``. Commands
    registered on the app itself (``@app.command``) are listed after the lazy ones.
    """

    lazy: tuple[LazyCommand, ...] = ()

    def _entry(self, name: str) -> LazyCommand | None:
        return next((e for e in self.lazy if e.name == name), None)

    def list_commands(self, ctx: Any) -> list[str]:
        names = [e.name for e in self.lazy]
        return names + [n for n in self.commands if n not in names]

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        command = self.commands.get(cmd_name)
        entry = self._entry(cmd_name)
        if command is None and entry is not None:
            command = self.commands[cmd_name] = load_command(entry, self.rich_markup_mode)
        return command

    def _listed_help(self, ctx: Any, name: str) -> str | None:
        entry = self._entry(name)
        if entry is not None and name not in self.commands:
            return entry.help  # listed without importing the command's module
        return super()._listed_help(ctx, name)

    def resolve_command(self, ctx: Any, args: list[str]) -> Any:
        try:
            return super().resolve_command(ctx, args)
        except Exception as e:
            # typer suggests close names from the commands loaded so far; add the lazy ones
            # (click's UsageError: typer may vendor its own click, so match the interface)
            message = getattr(e, "message", None)
            if args and isinstance(message, str) and "Did you mean" not in message:
                matches = difflib.get_close_matches(args[0], self.list_commands(ctx))
                if matches and message.startswith("No such command"):
                    e.message = (  # type: ignore[attr-defined]
                        f"{message.rstrip('.')}. Did you mean "
                        f"{', '.join(repr(m) for m in matches)}?"
                    )
            raise


#: Modules that the libraries a command imports load without using them, deferred until
#: first used (:func:`defer_unused_imports`). scipy (≥ 1.15) vendors ``array_api_compat``, whose
#: ``numpy`` namespace runs ``from numpy import *``: numpy 2's ``__all__`` names ``f2py``, so
#: every ``import scipy.linalg`` / ``scipy.spatial`` executed numpy's Fortran wrapper
#: generator (``numpy.f2py.crackfortran``: ~0.1 s of regular-expression compiling, holding the
#: interpreter while the first scan's thread and the toolpath's reader both wanted it).
DEFERRED_MODULES = frozenset({"numpy.f2py"})


class _DeferredFinder:
    """A meta-path finder (``importlib.abc.MetaPathFinder``'s protocol; not subclassed: that
    module costs ``roboisf --help`` 4 ms of imports) that hands out :data:`DEFERRED_MODULES`
    through :class:`importlib.util.LazyLoader` (the standard library's lazy import): the module
    object exists at once, its code runs on the first attribute read. Any other name: ``None``
    (the next finder's)."""

    def find_spec(self, fullname: str, path: Any, target: Any = None) -> Any:
        if fullname not in DEFERRED_MODULES:
            return None
        import importlib.machinery
        import importlib.util

        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        spec.loader = importlib.util.LazyLoader(spec.loader)
        return spec


def defer_unused_imports() -> None:
    """Defer the :data:`DEFERRED_MODULES` in this process (idempotent). For the console script
    only (:func:`roboisf.cli.main.entry`): a library caller's imports stay as they are.
    Measured in docs/speed.md ("numpy's Fortran wrapper generator").

    Nothing in roboisf reads ``numpy.f2py``; whoever does gets it whole on that first read.
    (Python 3.11's ``LazyLoader`` does not guard two threads making that first read at the
    same moment — CPython issue gh-114763, fixed in later releases — which no roboisf command
    does.)"""
    if not any(isinstance(f, _DeferredFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _DeferredFinder())
