"""Making the folders a command writes into."""

from __future__ import annotations

import errno
import time
from pathlib import Path


def make_folder(path: Path) -> None:
    """``mkdir -p``; a path that is a file raises NotADirectoryError saying so, where mkdir
    says only "File exists", which reads as no error at all."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise NotADirectoryError(errno.ENOTDIR, "exists and is not a folder", str(path)) from None


def run_dir_for(base: Path, project: str) -> Path:
    """Make and return ``runs/<project>-<timestamp>``, suffixed ``-2``, ``-3``… when runs start in
    the same second. Made here, not just named: two processes naming it at the same moment
    would otherwise both take the same folder (or one fail on it)."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    make_folder(base)
    n = 1
    while True:
        candidate = base / (f"{project}-{stamp}" if n == 1 else f"{project}-{stamp}-{n}")
        try:
            candidate.mkdir()
            return candidate
        except FileExistsError:
            n += 1
