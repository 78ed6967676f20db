"""The optional parts of hycosim and the import names each one brings.

``pip install hycosim`` is what coupling FMUs and Python nodes needs. The paper's scenario
(``[scenario]``: MuJoCo, OpenCV, torch, gymnasium, pythonfmu), the dashboard's web stack
(``[dashboard]``), figures (``[plot]``, matplotlib) and packaging Python models as FMUs
(``[models]``: pythonfmu, pythonfmu3) and Parquet records (``[parquet]``: pyarrow) are extras; a command or a node that
needs one that is missing names the extra to install instead of failing on an import.
Keep this table in step with ``[project.optional-dependencies]`` in ``pyproject.toml``
(a test compares them).
"""

from __future__ import annotations

import importlib.util

EXTRAS: dict[str, tuple[str, ...]] = {
    "scenario": ("mujoco", "cv2", "torch", "gymnasium", "pythonfmu", "matplotlib"),
    "dashboard": ("starlette", "uvicorn", "websockets"),
    "plot": ("matplotlib",),
    "models": ("pythonfmu", "pythonfmu3"),
    "parquet": ("pyarrow",),
}


def missing_modules(extra: str) -> list[str]:
    """The import names of ``extra`` that this Python cannot find (nothing is imported)."""
    return [name for name in EXTRAS[extra] if importlib.util.find_spec(name) is None]


def install_hint(extra: str) -> str:
    """How to install ``extra``, as a user types it."""
    return f"pip install 'hycosim[{extra}]'"


def extra_providing(module: str | None) -> str | None:
    """The extra whose packages provide the top-level module ``module`` (as an ImportError names
    it), or None when it belongs to none of them."""
    top = (module or "").partition(".")[0]
    return next((extra for extra, names in EXTRAS.items() if top in names), None)
