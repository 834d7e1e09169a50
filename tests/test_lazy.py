"""roboisf._lazy.attach: a package's exported names load their module on first use (PEP 562)."""

from __future__ import annotations

import importlib
import sys
import types

import pytest

from roboisf._lazy import attach


@pytest.fixture
def package(tmp_path, monkeypatch):
    """A throw-away package ``lazypkg`` with two submodules that count their imports."""
    root = tmp_path / "lazypkg"
    root.mkdir()
    (root / "__init__.py").write_text(
        "from roboisf._lazy import attach\n"
        "_WHERE = {'alpha': ('A', 'f'), 'beta': ('B',)}\n"
        "__all__ = ['A', 'B', 'f']\n"
        "__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)\n"
    )
    for name, body in (
        ("alpha", "class A: pass\ndef f(): return 42\n"),
        ("beta", "B = object()\n"),
    ):
        (root / f"{name}.py").write_text(
            f"import builtins\nbuiltins._lazy_log.append({name!r})\n{body}"
        )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr("builtins._lazy_log", [], raising=False)
    yield importlib.import_module("lazypkg")
    for m in [m for m in sys.modules if m == "lazypkg" or m.startswith("lazypkg.")]:
        del sys.modules[m]


def test_a_name_loads_only_its_module_once(package):
    import builtins

    assert builtins._lazy_log == []  # importing the package imports no submodule
    assert package.f() == 42
    assert builtins._lazy_log == ["alpha"]
    assert package.A is sys.modules["lazypkg.alpha"].A
    assert "A" in vars(package)  # stored: the next look-up does not go through __getattr__
    assert builtins._lazy_log == ["alpha"]
    assert package.B is sys.modules["lazypkg.beta"].B
    assert builtins._lazy_log == ["alpha", "beta"]
    from lazypkg import B  # noqa: F401  (the from-import form works too)


def test_unknown_names_and_dir(package):
    with pytest.raises(AttributeError, match="module 'lazypkg' has no attribute 'nope'"):
        package.nope  # noqa: B018
    assert {"A", "B", "f"} <= set(dir(package))
    assert dir(package) == sorted(set(dir(package)))
    assert package._MODULE_OF == {"A": "alpha", "f": "alpha", "B": "beta"}


def test_mistakes_in_the_table_are_refused():
    ns: dict[str, object] = {"__all__": ["x"]}
    with pytest.raises(ValueError, match=r"'x' is exported by both \.a and \.b"):
        attach("p", ns, {"a": ("x",), "b": ("x",)})
    with pytest.raises(ValueError, match=r"p.__all__ differs .*\['y'\]"):
        attach("p", ns, {"a": ("x", "y")})
    # a stale entry (the module no longer has the name) fails on use, naming it
    getattr_, _, _ = attach("json", {}, {"decoder": ("NoSuchThing",)})
    with pytest.raises(AttributeError, match="NoSuchThing"):
        getattr_("NoSuchThing")
    assert isinstance(sys.modules["json.decoder"], types.ModuleType)


def test_a_leading_dot_loads_from_a_sibling_package_lazily(tmp_path, monkeypatch):
    # roboisf.toolpath re-exports Toolpath from roboisf.path this way: lazily, like its own names
    for name in ("top", "top/low", "top/high"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text("")
    (tmp_path / "top/low/value.py").write_text(
        "import builtins\nbuiltins._lazy_log.append('low.value')\nV = object()\n"
    )
    (tmp_path / "top/high/__init__.py").write_text(
        "from roboisf._lazy import attach\n"
        "_WHERE = {'.low.value': ('V',)}\n"
        "__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr("builtins._lazy_log", [], raising=False)
    try:
        import builtins

        high = importlib.import_module("top.high")
        assert builtins._lazy_log == []
        assert high.V is importlib.import_module("top.low.value").V
        assert builtins._lazy_log == ["low.value"]
    finally:
        for m in [m for m in sys.modules if m == "top" or m.startswith("top.")]:
            del sys.modules[m]
