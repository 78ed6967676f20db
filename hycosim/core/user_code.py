"""Importing the code a project file names: ``module:Class`` or ``path/to/file.py:Class``.

A module beside the project file loads without the user setting PYTHONPATH: ``module`` is
looked up on the import path with the project file's folder last on it (so that a module there
never shadows an installed one, nor the standard library; processes run ``python -P``), and
``file.py`` names a file relative to the project file.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from typing import Any


def import_module(module_name: str, project_dir: Path):
    """The module a target names: a ``.py`` file relative to ``project_dir``, or a module on the
    import path, with that folder last on it. Raises what importing it raises."""
    if module_name.endswith(".py"):
        path = (project_dir / module_name).resolve()
        if not path.is_file():
            raise ImportError(f"no file {path}")
        name = f"hycosim_model_{path.stem}_{abs(hash(str(path))):x}"
        if name not in sys.modules:
            spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            try:
                spec.loader.exec_module(module)
            except BaseException:
                del sys.modules[name]
                raise
        return sys.modules[name]
    folder = str(project_dir.resolve())
    if folder not in sys.path:
        sys.path.append(folder)
    return importlib.import_module(module_name)


def import_target(target: str, project_dir: Path) -> Any:
    """The object ``module:Name`` (or ``file.py:Name``) names. ValueError for a target of
    another form; what importing raises otherwise (the caller names the entry)."""
    module_name, _, attr = target.rpartition(":")
    if not module_name or not attr:
        raise ValueError(f"{target!r} is neither 'module:Class' nor 'file.py:Class'")
    return getattr(import_module(module_name, project_dir), attr)
