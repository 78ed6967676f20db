"""Deprecated since 0.3.0: FMU import is :mod:`hycosim.fmi`, FMU export :mod:`hycosim.bridge`.
Kept for one release so that code importing the old names still runs."""

import warnings

warnings.warn("hycosim.fmu_bridge is deprecated since 0.3.0 and goes in 0.4.0: import hycosim.fmi (loading "
              "FMUs) or hycosim.bridge (building bridge and model FMUs)", DeprecationWarning, stacklevel=2)
