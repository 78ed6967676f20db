"""``hycosim`` and ``python -m hycosim``: the command line, its imports included.

The command's modules take about half a second to import, before its own signal handling is
set up: Ctrl-C then (a person who changed their mind at once) ended the process with a
traceback and no exit status of its own.
"""

import sys


def main() -> None:
    """Import the command line and run it; a stop signal during the imports is a way out too."""
    try:
        from hycosim.cli import main as cli_main
    except KeyboardInterrupt:
        sys.stderr.write("interrupted by Ctrl-C\n")
        sys.exit(130)
    cli_main()


if __name__ == "__main__":
    main()
