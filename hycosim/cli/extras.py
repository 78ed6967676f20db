"""A command that needs one of hycosim's extras says which one, before it imports anything of it."""

from __future__ import annotations

from hycosim.cli.output import fail
from hycosim.core.extras import install_hint, missing_modules


def require_extra(extra: str, command: str) -> None:
    """Exit 2 naming ``extra`` and how to install it when any of its packages is missing."""
    missing = missing_modules(extra)
    if missing:
        fail(f"{command} needs hycosim's [{extra}] extra ({', '.join(missing)} not installed): {install_hint(extra)}")
