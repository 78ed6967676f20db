"""hycosim: hybrid time/event co-simulation on the FMI standard, relayed over Eclipse Zenoh.

``hycosim.core`` holds the project file, frames, keys and sessions; ``hycosim.fmu_bridge``
everything FMU and SSP; ``hycosim.server`` the relay and its coordinator; ``hycosim.clients``
the node runtime and the nodes; ``hycosim.dashboard`` the web dashboard; ``hycosim.cli`` the
command line.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    # One version string: the package's metadata, written from pyproject.toml at install.
    __version__ = version("hycosim")
except PackageNotFoundError:  # the source tree on the import path, never installed
    __version__ = "0+unknown"
