"""Lazy package exports (PEP 562): a package's public names import their module on first use.

``roboisf.parts``, ``roboisf.toolpath``, ``roboisf.io``, ``roboisf.cam``, ``roboisf.logs``,
``roboisf.programs``, ``roboisf.robot``, ``roboisf.scan`` and ``roboisf.study`` re-export names
from modules that import numpy, scipy or pandas; loading those only when a name is
used keeps ``roboisf --help`` and the argument checks free of them (docs/conventions.md, Command
start-up). The same pattern
as Scientific Python's SPEC 1 (``lazy_loader.attach``), in a dozen lines instead of a dependency.
A package uses it as::

    _WHERE = {"mesh": ("MeshPart", "tessellate"), ...}   # module → the names it exports
    __getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)

with ``__all__`` spelled out and the names imported under ``TYPE_CHECKING`` for type checkers.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Mapping
from typing import Any

__all__ = ["attach"]


def attach(
    package: str, namespace: dict[str, Any], where: Mapping[str, Iterable[str]]
) -> tuple[Callable[[str], Any], Callable[[], list[str]], dict[str, str]]:
    """Module ``__getattr__`` and ``__dir__`` that load each exported name from its module.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    namespace : dict
        The package's ``globals()``; a loaded name is stored there, so later look-ups are plain
        attribute access.
    where : mapping of str to iterable of str
        Submodule name (relative to ``package``) → the names it exports. A name with a leading
        dot climbs out of the package as a relative import does (``".path.toolpath"`` in
        ``roboisf.toolpath`` is ``roboisf.path.toolpath``): a package re-exports a lower
        package's object without importing it eagerly.

    Returns
    -------
    getattr : callable
        For the package's ``__getattr__``: ``name`` → the object; ``AttributeError`` for a name
        that is not exported.
    dir : callable
        For the package's ``__dir__``: the namespace and every exported name, sorted.
    module_of : dict of str to str
        Exported name → submodule.

    Raises
    ------
    ValueError
        A name is exported by two submodules, or the package's ``__all__`` (when it has one)
        is not exactly the exported names.
    """
    module_of: dict[str, str] = {}
    for module, names in where.items():
        for name in names:
            if name in module_of:
                raise ValueError(
                    f"{package}: {name!r} is exported by both .{module_of[name]} and .{module}"
                )
            module_of[name] = module
    listed = namespace.get("__all__")
    if listed is not None and sorted(listed) != sorted(module_of):
        raise ValueError(
            f"{package}.__all__ differs from the lazily exported names: "
            f"{sorted(set(listed) ^ set(module_of))}"
        )

    def __getattr__(name: str) -> Any:
        module = module_of.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted({*namespace, *module_of})

    return __getattr__, __dir__, module_of
