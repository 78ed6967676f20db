"""Making the folders a command writes into."""

from __future__ import annotations

import errno
from pathlib import Path


def make_folder(path: Path) -> None:
    """``mkdir -p``; a path that is a file raises NotADirectoryError saying so, where mkdir
    says only "File exists", which reads as no error at all."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise NotADirectoryError(errno.ENOTDIR, "exists and is not a folder", str(path)) from None
