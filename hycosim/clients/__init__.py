"""Deprecated since 0.3.0: the node runtime is :mod:`hycosim.node`, the grasp demo's nodes
:mod:`hycosim.scenario`. Kept for one release so that code importing the old names still runs."""

import warnings

warnings.warn("hycosim.clients is deprecated since 0.3.0 and goes in 0.4.0: import hycosim.node "
              "(the node interface and runtime) or hycosim.scenario (the grasp demo's nodes)",
              DeprecationWarning, stacklevel=2)
