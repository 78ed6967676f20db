"""The package's folders show its architecture (docs/layout.md): the grasp demo is a user of
the framework, the shared core imports nothing above it, server and node never meet, and the
names before 0.3.0 still import, with a DeprecationWarning."""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from tests.helpers import REPO

PACKAGE = REPO / "hycosim"
# The 0.2.0 names kept for one release: they are the only modules allowed to import the new
# names across the rules below' lines, and they are checked on their own.
DEPRECATED = {PACKAGE / "clients", PACKAGE / "fmu_bridge"}


def _modules(deprecated: bool = False) -> list[Path]:
    return [p for p in PACKAGE.rglob("*.py") if "build" not in p.relative_to(PACKAGE).parts
            and (deprecated or not any(d in p.parents for d in DEPRECATED))]


def _imports(path: Path) -> set[str]:
    """Every module a file imports, at its top or inside a function (from-imports as the
    module and each name beneath it, since ``from hycosim import scenario`` imports it too)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module":
            found.update(a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str))
    return found


def _under(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


def test_nothing_outside_the_scenario_and_the_command_line_imports_the_grasp_demo():
    offenders = []
    for path in _modules(deprecated=True):  # the old names' modules too
        rel = path.relative_to(PACKAGE)
        if rel.parts[0] in ("scenario", "cli"):
            continue
        offenders += [f"{rel}: imports {m}" for m in _imports(path) if _under(m, "hycosim.scenario")]
        # Its name written anywhere counts too: a model target a loader would import later, a
        # hint sending a user there (the demo's models go by their registered names).
        offenders += [f"{rel}:{n}: names it" for n, line in enumerate(path.read_text().splitlines(), 1)
                      if re.search(r"hycosim[./]scenario", line)]
    assert not offenders, offenders


def test_the_command_line_imports_the_grasp_demo_only_to_register_its_commands():
    for path in (PACKAGE / "cli").rglob("*.py"):
        demo = {m for m in _imports(path) if _under(m, "hycosim.scenario")}
        if path.name == "main.py" and path.parent.name == "cli":
            assert demo and all(_under(m, "hycosim.scenario.commands") for m in demo), demo
        else:
            assert not demo, (path, demo)


@pytest.mark.parametrize("package, never", [
    ("core", ("hycosim.transport", "hycosim.master", "hycosim.node", "hycosim.fmi", "hycosim.bridge",
              "hycosim.cli", "hycosim.dashboard", "hycosim.embedded", "hycosim.inprocess")),
    ("transport", ("hycosim.master", "hycosim.node", "hycosim.fmi", "hycosim.bridge", "hycosim.cli",
                   "hycosim.dashboard")),
    ("master", ("hycosim.node", "hycosim.cli", "hycosim.dashboard")),
    ("node", ("hycosim.master", "hycosim.cli", "hycosim.dashboard", "hycosim.embedded", "hycosim.inprocess")),
    ("fmi", ("hycosim.master", "hycosim.node", "hycosim.cli", "hycosim.dashboard", "hycosim.bridge")),
    ("bridge", ("hycosim.node", "hycosim.cli", "hycosim.dashboard")),
])
def test_each_folder_imports_only_what_lies_below_it(package, never):
    offenders = [f"{p.relative_to(PACKAGE)}: {m}" for p in (PACKAGE / package).rglob("*.py")
                 for m in _imports(p) if any(_under(m, n) for n in never)]
    assert not offenders, offenders


def test_the_names_before_0_3_0_import_with_a_deprecation_warning():
    """In a fresh interpreter (a module is imported once per process, and warns then)."""
    code = ("import warnings; warnings.simplefilter('error', DeprecationWarning)\n"
            "import importlib, sys\n"
            "for name in ('hycosim.clients.node', 'hycosim.fmu_bridge.model_fmu', 'hycosim.server.report'):\n"
            "    try:\n"
            "        importlib.import_module(name)\n"
            "    except DeprecationWarning as w:\n"
            "        print(name, 'WARNS', w)\n"
            "    else:\n"
            "        print(name, 'SILENT')\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert len(lines) == 3 and all(" WARNS " in line for line in lines), lines
    assert "hycosim.node" in lines[0] and "hycosim.bridge" in lines[1] and "hycosim.master" in lines[2], lines
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        old = importlib.import_module("hycosim.clients.node")
        from hycosim.bridge.model_fmu import build_model_fmu
        from hycosim.fmu_bridge.model_fmu import build_model_fmu as old_build
        from hycosim.server.report import read_meta as old_read_meta
    from hycosim.master.report import read_meta
    from hycosim.node import AsyncSource, Node, pack_state

    assert old.Node is Node and old.AsyncSource is AsyncSource and old.pack_state is pack_state
    assert old_build is build_model_fmu and old_read_meta is read_meta


def test_the_grasp_demos_models_and_fmu_builders_are_found_through_entry_points(tmp_path):
    from hycosim.core.schema import Node as NodeSpec
    from hycosim.node.loader import NodeLoadError, REFERENCE_MODELS, _fmu_path, known_models

    known = known_models()
    assert set(REFERENCE_MODELS) < set(known)
    assert {"rod", "robot", "camera", "policy", "reference_controller"} <= set(known) - set(REFERENCE_MODELS)
    assert all(importlib.util.find_spec(target.partition(":")[0]) for target in known.values())
    # A missing scene FMU names the command its package registered; another FMU names none.
    for name, says in (("Rod.fmu", f"hycosim scene fmus -o {tmp_path}"), ("Gain.fmu", None)):
        spec = NodeSpec.model_validate({"nodeName": "n", "UID": 1, "fmu": name})
        with pytest.raises(NodeLoadError) as caught:
            _fmu_path(spec, tmp_path)
        message = str(caught.value)
        assert "does not exist" in message
        assert (says in message) if says else ("build" not in message and "hycosim" not in message), message
