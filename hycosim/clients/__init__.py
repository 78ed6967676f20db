"""Deprecated since 0.3.0: the node runtime is :mod:`hycosim.node`; the grasp demo's nodes are
named by the names they are registered under. Kept for one release so that code importing the
old names still runs."""

import warnings

warnings.warn("hycosim.clients is deprecated since 0.3.0 and goes in 0.4.0: import hycosim.node "
              "(the node interface and runtime); the grasp demo's models go by their registered "
              "names (rod, robot, reference_controller, camera, policy)",
              DeprecationWarning, stacklevel=2)
