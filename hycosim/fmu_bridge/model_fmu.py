"""Deprecated since 0.3.0: :mod:`hycosim.bridge.model_fmu`, re-exported here for one release."""

import warnings

from hycosim.bridge.model_fmu import ModelFmuError, build_model_fmu

__all__ = ["ModelFmuError", "build_model_fmu"]

warnings.warn("hycosim.fmu_bridge.model_fmu is deprecated since 0.3.0 and goes in 0.4.0: "
              "from hycosim.bridge.model_fmu import build_model_fmu", DeprecationWarning, stacklevel=2)
