"""Every public function, method, property and class of the package, and of the benchmarks, says
what it is for.

A method or property may take its text from the class it overrides or the interface it
implements (``inspect.getdoc`` looks through the bases, as ``help()`` does): an
implementation of :class:`hycosim.node.interface.Node` or of a transport's Protocol is
documented where the interface is. A class needs its own text; a dataclass's generated
signature is not one."""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import warnings
from collections.abc import Iterable, Iterator
from typing import Any

import hycosim
from tests.helpers import REPO

# Kept for one release under their 0.2.0 names; importing them warns (tests/test_layout.py).
DEPRECATED = ("hycosim.clients", "hycosim.fmu_bridge")


def _modules() -> list[Any]:
    """Every module of the package but the deprecated names (walking a package imports it)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        return [importlib.import_module(info.name) for info in pkgutil.walk_packages(hycosim.__path__, "hycosim.")
                if not (info.name.endswith("__main__") or info.name.startswith(DEPRECATED))]


def _own_class_text(cls: type) -> str:
    doc = vars(cls).get("__doc__") or ""
    if doc.startswith(f"{cls.__name__}("):  # what @dataclass and NamedTuple write where the class has none
        return ""
    return doc.strip()


def undocumented(modules: Iterable[Any]) -> Iterator[str]:
    """The public functions, classes, methods and properties of ``modules`` without a docstring
    (a method's or a property's may come from a base class), by dotted name."""
    for module in modules:
        for name, obj in vars(module).items():
            if name.startswith("_") or getattr(obj, "__module__", None) != module.__name__:
                continue
            where = f"{module.__name__}.{name}"
            if inspect.isfunction(obj):
                if not inspect.getdoc(obj):
                    yield where
            elif inspect.isclass(obj):
                if not _own_class_text(obj):
                    yield f"{where} (class)"
                for attr, member in vars(obj).items():
                    if attr.startswith("_"):
                        continue
                    if isinstance(member, (staticmethod, classmethod)):
                        member = member.__func__
                    if isinstance(member, property) or inspect.isfunction(member):
                        if not inspect.getdoc(getattr(obj, attr) if inspect.isfunction(member) else member):
                            yield f"{where}.{attr}"


def test_every_public_function_method_property_and_class_has_a_docstring():
    modules = _modules()
    assert len(modules) > 100  # the walk found the package
    missing = sorted(undocumented(modules))
    assert not missing, f"{len(missing)} without a docstring:\n" + "\n".join(missing)


def test_every_public_function_and_class_of_the_benchmarks_has_a_docstring():
    # The benchmarks are scripts (some import engines the tests do not install): read, not imported.
    missing = []
    for path in sorted((REPO / "benchmarks").glob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
                members = [node] + [m for m in getattr(node, "body", []) if isinstance(node, ast.ClassDef)
                                    and isinstance(m, ast.FunctionDef) and not m.name.startswith("_")]
                missing += [f"{path.name}: {m.name}" for m in members if ast.get_docstring(m) is None]
    assert not missing, "without a docstring:\n" + "\n".join(missing)


SAMPLE = '''
from dataclasses import dataclass


class Base:
    """A base."""

    def documented(self):
        """Said here."""

    @property
    def value(self):
        """A value."""


class Derived(Base):
    """Its own text."""

    def documented(self):
        pass

    @property
    def value(self):
        return 1

    def bare(self):
        pass

    def _private(self):
        pass


@dataclass
class Plain:
    x: int


def loose():
    return None
'''


def test_the_check_names_what_lacks_a_docstring_and_takes_an_inherited_one(tmp_path, monkeypatch):
    (tmp_path / "docstring_sample.py").write_text(SAMPLE)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("docstring_sample")
    assert sorted(undocumented([module])) == ["docstring_sample.Derived.bare", "docstring_sample.Plain (class)",
                                              "docstring_sample.loose"]
